"""The ground floor every other package stands on: records, the grammar of spans, the registry, the
message codecs, safe input and files, the stamp clock, routes, topic selection, why a trigger fired,
the errors. Imports nothing else of cc_log."""

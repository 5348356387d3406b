"""The one vocabulary of what happens to a logging window and its files: the kind of a writer's event
(``storage.window_writer.WriterEvent``), of the smart logger's (``logger.smart_events.Event``) and of the smart
node's ``~anomalies`` (``cc_log/AnomalyEvent``: its constants OPENED, WRITTEN and FAILED have these values on the
wire, so a kind is published as it is). Pure, imports nothing."""

__all__ = ['OPENED', 'WRITTEN', 'FAILED', 'SPLIT', 'DELETED']

OPENED = 0   # a trigger opened a window (the smart logger only); OPENED, WRITTEN, FAILED: said on ~anomalies
WRITTEN = 1  # a window file is on disk
FAILED = 2   # writing a window failed: held in memory and retried, or lost for good
SPLIT = 3    # a file of a window still being written finished at split_mb: the window goes on in the next
DELETED = 4  # an old window file deleted to stay within the quota (max_disk_mb, max_files)

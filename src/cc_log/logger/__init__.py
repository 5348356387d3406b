"""The smart logger and collect mode, their events, health and keep budget, the configuration and the
options. Imports every package below it: ``base``, ``buffer``, ``features``, ``learning``,
``storage``, ``triggers``."""

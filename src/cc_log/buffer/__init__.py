"""The window buffer (the deques around a Fire) and the preparation of a window for the writer.
Imports only ``base``."""

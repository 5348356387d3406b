"""Window file formats: one module per format, one table.

A format module defines ``CODEC`` (its name, e.g. ``'json-xz'``), ``EXTENSION``, ``MAGIC`` (the bytes every
file of it starts with), ``encoder(records, metadata)`` (a function that writes the window into a binary
stream; it may encode first, before the file exists), ``read(path, stream)`` -> ``(metadata, records)``
raising ``ValueError('<path>: ...')``, ``PART_FACTOR`` (memory a window part takes while it waits and is
written, per byte of its estimated size: the smart logger hands an open window on in parts at half its
memory budget divided by it), optionally ``RAW_RECORDS`` (records are handed over as serialized bytes, not
decoded), ``WindowStream`` (a window handed on in parts is written into one file, a part at a time:
``log_format.WindowFile``) and ``salvage(path)`` for a file cut off mid-write (``recovery``; see
``bag_salvage.Salvaged``). To add a format: its module here and one entry in ``FORMATS``.

The default is ``bag-lz4``: on cameras and lidars it costs about what ``rosbag record`` costs (LZ4 runs at
~1.4 GB/s a core, LZMA at ~16 MB/s: json-xz cannot keep up with a 30 Hz camera), its windows stream to disk
and open in rosbag, rqt_bag, PlotJuggler and Foxglove. ``json-xz`` stays the choice for robots whose kept
topics are light and numeric (odometry, IMU): 4-30x smaller there (docs/FORMAT.md), readable with ``cclog cat``.

Pure: a module that needs rosbag imports it inside its functions.
"""
import collections

from cc_log.storage.formats import bag_lz4, json_xz

FORMATS = collections.OrderedDict((module.CODEC, module) for module in (bag_lz4, json_xz))  # the first: default
DEFAULT = next(iter(FORMATS))


def names():
    """The format names, the default first."""
    return tuple(FORMATS)


def check(name, param='format'):
    """Return ``name`` when it is a format; else ValueError("format: 'xyz' is not one of: ...")."""
    if name not in FORMATS:
        raise ValueError('%s: %r is not one of: %s' % (param, name, ', '.join(FORMATS)))
    return name


def get(name, param='format'):
    """The module of format ``name`` (ValueError as ``check``)."""
    return FORMATS[check(name, param)]


def by_magic(head):
    """The module whose files start like ``head`` (the first 16 bytes of a file), else None."""
    return next((module for module in FORMATS.values() if head.startswith(module.MAGIC)), None)


def by_extension(path):
    """The module whose extension ``path`` ends with, else None."""
    return next((module for module in FORMATS.values() if path.endswith(module.EXTENSION)), None)


def extensions():
    """Every format's file extension."""
    return tuple(module.EXTENSION for module in FORMATS.values())

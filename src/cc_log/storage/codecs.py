"""The paper's Table 2: how each general-purpose codec does on given bytes.

``codec_table(data)`` compresses ``data`` with none, LZ4 (``lz4.frame``), LZFSE (only when a Python
binding imports), ZIP (``zipfile`` deflate), gzip, bzip2, LZMA-6 (xz) and zstd, checks that each
decompresses back to ``data``, and reports size, ratio and speed; ``format_table`` prints it.
Pure: standard library plus the optional python3-lz4 and python3-zstandard (reported unavailable when
missing).
"""
import bz2
import gzip
import io
import lzma
import math
import os
import tempfile
import time
import zipfile

MIN_SECONDS = 0.2  # compress repeatedly until this much time has passed, for a stable speed


def _zip_compress(data):
    stream = io.BytesIO()
    with zipfile.ZipFile(stream, 'w', compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr('data', data)
    return stream.getvalue()


def _zip_decompress(blob):
    with zipfile.ZipFile(io.BytesIO(blob)) as archive:
        return archive.read('data')


def _lz4():
    import lz4.frame
    return lz4.frame.compress, lz4.frame.decompress


def _lzfse():
    try:
        import lzfse
    except ImportError:
        import pyliblzfse as lzfse
    return lzfse.compress, lzfse.decompress


def _zstd():
    import zstandard
    compressor, decompressor = zstandard.ZstdCompressor(level=3), zstandard.ZstdDecompressor()
    return compressor.compress, decompressor.decompress


def _builtin(compress, decompress):
    return lambda: (compress, decompress)


#: (name, loader returning (compress, decompress)); in the order of the paper's table.
CODECS = [
    ('none', _builtin(bytes, bytes)),
    ('LZ4', _lz4),
    ('LZFSE', _lzfse),
    ('ZIP', _builtin(_zip_compress, _zip_decompress)),
    ('gzip', _builtin(lambda data: gzip.compress(data, 6), gzip.decompress)),
    ('bzip2', _builtin(lambda data: bz2.compress(data, 9), bz2.decompress)),
    ('LZMA-6', _builtin(lambda data: lzma.compress(data, preset=6), lzma.decompress)),
    ('zstd', _zstd),
]


def _speed(compress, data):
    runs, start = 0, time.perf_counter()
    while True:
        blob = compress(data)
        runs += 1
        elapsed = time.perf_counter() - start
        if elapsed >= MIN_SECONDS:
            return blob, elapsed / runs


def codec_table(data, codecs=None):
    """One dict per codec: codec, available, size (bytes), ratio (% of the input), mb_s (compress MB/s,
    1 MB = 10^6 bytes), note (why unavailable). ``codecs``: names to run (default all)."""
    data = bytes(data)
    rows = []
    for name, loader in CODECS:
        if codecs is not None and name not in codecs:
            continue
        try:
            compress, decompress = loader()
        except ImportError as error:
            rows.append({'codec': name, 'available': False, 'size': None, 'ratio': None, 'mb_s': None,
                         'note': 'no Python binding (%s)' % error})
            continue
        blob, seconds = _speed(compress, data)
        if decompress(blob) != data:
            raise AssertionError('%s: decompressed data differs from the input' % name)
        rows.append({'codec': name, 'available': True, 'size': len(blob),
                     'ratio': 100.0 * len(blob) / len(data) if data else 0.0,
                     'mb_s': len(data) / 1e6 / seconds if seconds > 0 else float('inf'), 'note': ''})
    return rows


def window_format_rows(records, raw_bytes):
    """cc_log's own window formats on the same records, as ``codec_table`` rows (size, ratio in %
    of the raw JSON, MB/s of raw JSON through ``log_format.write_window``, file write and fsync included)."""
    from cc_log.storage import log_format
    from cc_log.base.records import LogWindow, Trigger
    rows = []
    window = LogWindow(records, [Trigger(records[0].stamp, 'codecs', None)])
    folder = tempfile.mkdtemp(prefix='cclog-codecs-')
    try:
        for fmt in log_format.Format.ALL:
            started = time.perf_counter()
            path, size = log_format.write_window(window, folder, fmt, {})
            seconds = time.perf_counter() - started
            os.unlink(path)
            rows.append({'codec': 'cc_log %s' % fmt, 'available': True, 'size': size,
                         'ratio': 100.0 * size / raw_bytes if raw_bytes else 0.0,
                         'mb_s': raw_bytes / 1e6 / seconds if seconds > 0 else None,
                         'note': 'window file, one write'})
    finally:
        for name in os.listdir(folder):
            os.unlink(os.path.join(folder, name))
        os.rmdir(folder)
    return rows


def format_table(rows):
    """``codec_table`` rows (plus ``window_format_rows``) as a text table, the codec column as wide as its names."""
    width = max([len('codec')] + [len(row['codec']) for row in rows])
    lines = ['%-*s %12s %8s %10s' % (width, 'codec', 'bytes', 'ratio', 'MB/s')]
    for row in rows:
        if row['available']:
            speed = row['mb_s']
            lines.append('%-*s %12d %7.2f%% %10s  %s' % (
                width, row['codec'], row['size'], row['ratio'],
                '%.1f' % speed if speed is not None and math.isfinite(speed) else '-', row.get('note') or ''))
        else:
            lines.append('%-*s %12s %8s %10s  %s' % (width, row['codec'], '-', '-', '-', row.get('note') or ''))
    return '\n'.join(line.rstrip() for line in lines)

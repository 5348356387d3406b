"""Property-based fuzzing of every reader and parser (issue 42): hostile inputs from ``fuzz_strategies`` run
against every entry point where outside data comes in.

Each call must (``bounded``):
- let nothing but ``ValueError`` escape (``cc_log.base.errors``' classes are ValueErrors);
- finish within ``MAX_SECONDS`` of CPU time (the machine is shared: CPU time, not wall time, is what the
  reader spends), and within ``MAX_WALL_SECONDS`` of wall time (a call that waits);
- grow the resident set by at most ``MAX_GROWTH_MB`` at its peak (``VmHWM`` reset before each call: what the
  call touched, not what it reserved; a ``cclog`` process itself takes ~150 MB, so this keeps a command under
  the 600 MB of offline tools);
- write nothing outside its example's directory (each example gets its own root; the working directory is
  an empty directory inside it, and afterwards the root holds just what the example put there, plus, for
  ``recovery.recover`` only, files in the leftover's own directory).

Settings: a fixed seed (``derandomize``), ``CC_LOG_FUZZ_EXAMPLES`` examples per test (default 15: the file
runs in under a minute); the longer run of docs/RELIABILITY.md (``tools/fuzz_long.sh``) runs rounds of more
examples, each round with its own ``CC_LOG_FUZZ_SEED``; ``CC_LOG_FUZZ_FINDINGS``: a directory where the input
files of a call past a bound are copied.
"""
import functools
import os
import shutil
import signal
import tempfile
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

import fuzz_strategies as fs
from cc_log.logger import config, options
from cc_log.base import raw_message, safe_files, spans
from cc_log.learning.envelope import Envelope
from cc_log.learning.learning import load_vectors
from cc_log.learning.model import AnomalyModel
from cc_log.base.safe_input import printable
from cc_log.nodes import record_main
from cc_log.offline import stats, sweep, top
from cc_log.storage import formats, log_format, recovery, window_names
from cc_log.storage.bag import bag_open, bag_reader, bag_salvage, bagio

pytest.importorskip('rosbag')

EXAMPLES = int(os.environ.get('CC_LOG_FUZZ_EXAMPLES', '15'))
MAX_SECONDS = 5.0
MAX_WALL_SECONDS = 60  # a call that waits (no CPU spent) fails too; generous: the machine may be shared
MAX_GROWTH_MB = 450
DEAD_PID = safe_files.PID_MAX + 1  # names no process (``safe_files.pid_of``): no writer holds the leftover
FINDINGS = os.environ.get('CC_LOG_FUZZ_FINDINGS')  # a directory: inputs past a bound are copied there
WINDOW = 'cc_log_20150521T191138.027Z_classifier'

SEED = os.environ.get('CC_LOG_FUZZ_SEED')  # another seed: other examples (the longer run's rounds)
FUZZ = settings(max_examples=EXAMPLES, derandomize=SEED is None, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])


def fuzz(test, examples=EXAMPLES, **options):
    """``test`` (a hypothesis test) with the fuzzing settings: ``examples``, the fixed seed (or SEED's), and
    ``options`` (other hypothesis settings)."""
    test = settings(FUZZ, max_examples=examples, **options)(test)
    return seed(int(SEED))(test) if SEED is not None else test


def _rss_kb(key):
    """``VmHWM`` (the peak resident set since the last reset) or ``VmRSS`` of this process, in kB."""
    with open('/proc/self/status') as stream:
        for line in stream:
            if line.startswith(key + ':'):
                return int(line.split()[1])
    raise ValueError('/proc/self/status: no %s' % key)


class _Hung(BaseException):
    """Raised in a call still running after MAX_WALL_SECONDS (a BaseException: no reader's ``except Exception``
    turns it into a ValueError)."""


def _hung(signum, frame):
    raise _Hung('still running after %d s of wall time (waiting on something?)' % MAX_WALL_SECONDS)


def _reset_peak():
    """Make ``VmHWM`` start again from the resident set now (``clear_refs`` 5, Linux 4.0)."""
    with open('/proc/self/clear_refs', 'w') as stream:
        stream.write('5')


def bounded(call, *args, max_growth_mb=MAX_GROWTH_MB, since_kb=None):
    """``call(*args)`` (a generator is consumed into a list) within the bounds; its result, or the ValueError it
    raised. Any other exception fails the test. ``since_kb``: the resident set (kB) the growth is counted from,
    the peak not reset (calls that share what they hold, such as a logger's); None: this call's own."""
    if since_kb is None:
        _reset_peak()
    before = _rss_kb('VmRSS') if since_kb is None else since_kb
    started = time.process_time()
    signal.signal(signal.SIGALRM, _hung)
    signal.alarm(MAX_WALL_SECONDS)
    try:
        result = call(*args)
        if hasattr(result, '__next__'):
            result = list(result)
    except ValueError as error:
        result = error
    finally:
        signal.alarm(0)
    spent = time.process_time() - started
    grown = (_rss_kb('VmHWM') - before) / 1e3
    if (spent >= MAX_SECONDS or grown >= max_growth_mb) and FINDINGS:
        _keep(args)
    name = getattr(call, '__qualname__', call)
    assert spent < MAX_SECONDS, '%s took %.1f s of CPU' % (name, spent)
    assert grown < max_growth_mb, '%s grew the resident set by %.0f MB' % (name, grown)
    if isinstance(result, ValueError):
        assert str(result) and '\n' not in str(result).strip(), 'not one line: %r' % str(result)[:300]
    return result


def _keep(args):
    """Copy the input files among ``args`` into ``FINDINGS`` (to reproduce a finding outside hypothesis)."""
    os.makedirs(FINDINGS, exist_ok=True)
    for arg in args:
        if isinstance(arg, str) and os.path.isfile(arg):
            shutil.copy(arg, os.path.join(FINDINGS, '%d_%s' % (time.time() * 1e3, os.path.basename(arg))))


class Root(object):
    """An example's own directory: ``put(name, data)`` writes an input into ``<root>/in``; the working directory
    is ``<root>/cwd`` while it is open; on leaving, ``<root>`` must hold only ``in`` and an empty ``cwd``, and
    ``in`` only what was put there (``allow_in``: anything in ``in`` too)."""

    def __init__(self, allow_in=False):
        self.allow_in = allow_in

    def __enter__(self):
        self.path = tempfile.mkdtemp(prefix='cc_log_fuzz_')
        self.input = os.path.join(self.path, 'in')
        os.makedirs(self.input)
        os.mkdir(os.path.join(self.path, 'cwd'))
        self.put_names = set()
        self.old_cwd = os.getcwd()
        os.chdir(os.path.join(self.path, 'cwd'))
        return self

    def put(self, name, data, under=None):
        folder = os.path.join(self.input, under) if under else self.input
        os.makedirs(folder, exist_ok=True)
        path = os.path.join(folder, name)
        with open(path, 'wb') as stream:
            stream.write(data)
        self.put_names.add(os.path.relpath(path, self.input))
        return path

    def __exit__(self, kind, value, traceback):
        os.chdir(self.old_cwd)
        try:
            if kind is None:
                assert sorted(os.listdir(self.path)) == ['cwd', 'in'], os.listdir(self.path)
                assert os.listdir(os.path.join(self.path, 'cwd')) == []
                found = set(os.path.relpath(os.path.join(folder, name), self.input)
                            for folder, _, names in os.walk(self.input) for name in names)
                if not self.allow_in:
                    assert found == self.put_names, 'written: %s' % sorted(found - self.put_names)
        finally:
            shutil.rmtree(self.path)


# -- bags --------------------------------------------------------------------------------------------------

BAG_TOPICS = ['/odom', '/imu']


@fuzz
@given(bag=fs.bags())
def test_hostile_bags_in_every_bag_reader(bag):
    name, data = bag
    with Root() as root:
        path = root.put(name, data)
        bounded(bag_reader.read_raw, path, BAG_TOPICS)
        bounded(bagio.read_messages, path, ['/odom'])
        bounded(bag_open.read_raw, path, BAG_TOPICS)
        bounded(bag_salvage.salvage, path)


def read_as_window(path, fmt):
    """Every reader of one window file, each bounded."""
    bounded(log_format.read_window, path)
    bounded(log_format.read_metadata, path)
    bounded(formats.get(fmt).read, path)


@fuzz
@given(bag=fs.bags())
def test_hostile_bags_as_windows(bag):
    _, data = bag
    with Root() as root:
        read_as_window(root.put(WINDOW + '.bag', data), 'bag-lz4')


# -- json-xz -----------------------------------------------------------------------------------------------

@fuzz
@given(data=fs.json_xz_documents())
def test_hostile_json_xz_documents(data):
    with Root() as root:
        read_as_window(root.put(WINDOW + '.json.xz', data), 'json-xz')


@fuzz
@given(document=fs.json_xz_documents(), bag=fs.bags(), split=st.booleans())
def test_hostile_window_sets(document, bag, split):
    with Root() as root:
        own = root.put(WINDOW + '.json.xz', document)
        root.put(WINDOW + ('.001.bag' if split else '+r.bag'), bag[1])
        sets = bounded(log_format.window_sets, [own])
        assert sets == [sorted(sets[0], key=window_names.file_order)] and len(sets[0]) == 2
        bounded(log_format.read_window_set, sets[0])


# -- recovery of leftovers (writes, in the leftover's directory only; nothing lost) ------------------------

def check_recover(root, path, data):
    outcome = bounded(recovery.recover, path)
    if isinstance(outcome, ValueError):
        pytest.fail('a leftover of a valid name refused: %s' % outcome)
    kept = set()
    for folder, _, names in os.walk(root.input):
        for name in names:
            with open(os.path.join(folder, name), 'rb') as stream:
                kept.add(stream.read())
    if data not in kept:  # its bytes are gone: nothing of it may be lost
        assert outcome.status in (recovery.EMPTY, recovery.PARTIAL, recovery.DUPLICATE), outcome
        assert outcome.lost_bytes == 0, outcome
    if outcome.path:
        _, records = log_format.read_window(outcome.path)
        assert len(records) == outcome.messages, outcome


@fuzz
@given(bag=fs.bags(), document=fs.json_xz_documents(), which=st.booleans())
def test_hostile_leftovers_recovered_in_their_directory_losing_nothing(bag, document, which):
    with Root(allow_in=True) as root:
        data = bag[1] if which else document
        extension = '.bag' if which else '.json.xz'
        path = root.put('%s%s%s%d' % (WINDOW, extension, log_format.TMP_MARK, DEAD_PID), data, under='dir')
        check_recover(root, path, data)


# -- models, envelopes, feature vectors --------------------------------------------------------------------

def _use_file(data, name, use):
    """``use(path)`` of ``data`` written as ``name``, bounded."""
    with Root() as root:
        bounded(use, root.put(name, data))


def _use_model(path):
    model = AnomalyModel.load(path)
    return model.score(np.zeros(model.dimension))


@fuzz
@given(data=fs.model_documents())
def test_hostile_model_files(data):
    _use_file(data, 'model.json', _use_model)


@fuzz
@given(data=fs.envelope_documents())
def test_hostile_envelope_files(data):
    _use_file(data, 'envelope.json', lambda path: Envelope.load(path).limits())


@fuzz
@given(data=fs.vector_documents(), more=fs.vector_documents())
def test_hostile_feature_vector_files(data, more):
    with Root() as root:
        root.put('1432235498.500000.json', data, under='vectors/normal')
        root.put('1432235499.500000.json', more, under='vectors/normal')
        bounded(load_vectors, os.path.join(root.input, 'vectors'), True)


# -- configuration and options -----------------------------------------------------------------------------

def _use_config(path):
    data = config.load_file(path)
    checked = config.Config.from_dict(data, path)
    checked.build_triggers(AnomalyModel.load, raw_message.installed_class)
    return checked


@fuzz
@given(data=fs.config_documents())
def test_hostile_configuration_files(data):
    with Root() as root:
        bounded(_use_config, root.put('config.yaml', data))


OPTIONS = list(options.OPTIONS) + list(options.TOPIC_OPTIONS)


@pytest.mark.parametrize('option', OPTIONS, ids=[o.name for o in OPTIONS])
@functools.partial(fuzz, examples=max(5, EXAMPLES // 4))
@given(value=fs.option_values(), text=st.one_of(st.sampled_from(fs._EDGE_TEXTS), st.text(max_size=30)))
def test_every_option_parser_takes_any_value(option, value, text):
    with Root():
        bounded(option.parse, value)
        bounded(option.parse, text, option.flag)


PARSERS = [spans.Span.parse, spans.seconds, spans.megabytes, spans.Rotation.parse, options.parse_topic_limits]


@pytest.mark.parametrize('parser', PARSERS, ids=[p.__qualname__ for p in PARSERS])
@fuzz
@given(value=fs.option_values())
def test_every_grammar_parser_takes_any_value(parser, value):
    with Root():
        bounded(parser, value)


def _record_arguments(texts):
    return record_main.parse([text for text in texts if not text.lstrip('-').startswith('h')])  # not --help


TEXT_PARSERS = [record_main.parse_size, record_main.parse_split_size, record_main.parse_duration,
                functools.partial(stats.parse_time, name='--start'), lambda text: sweep.parse_sweep([text]),
                lambda text: _record_arguments(text.split())]
TEXT_PARSER_NAMES = ['record.parse_size', 'record.parse_split_size', 'record.parse_duration', 'stats.parse_time',
                     'sweep.parse_sweep', 'record.parse']


@pytest.mark.parametrize('parser', TEXT_PARSERS, ids=TEXT_PARSER_NAMES)
@fuzz
@given(text=st.one_of(st.sampled_from(fs._EDGE_TEXTS), st.text(max_size=40),
                      st.lists(st.sampled_from(fs._EDGE_TEXTS + ['-a', '-e', '-o', '--split', '--size', '-x', '--node',
                                                                 '--duration', '1', '-j', '--lz4', '-b', '0']),
                               max_size=6).map(' '.join)))
def test_every_command_line_parser_takes_any_text(parser, text):
    with Root():
        bounded(parser, text)


# -- /diagnostics ------------------------------------------------------------------------------------------

def _listen(batches):
    statuses = top.Statuses()
    lines = []
    for heard, now in batches:
        statuses.heard(heard, now)
        view = statuses.view(now)
        assert len(view) <= top.MAX_NODES
        for name, (_, message, values) in view.items():
            assert len(name) <= top.MAX_TEXT and len(message) <= top.MAX_TEXT and len(values) <= top.MAX_VALUES
            assert all(len(k) <= top.MAX_TEXT and len(v) <= top.MAX_TEXT for k, v in values.items())
        lines = top.render(view)
    return lines


@fuzz
@given(batches=fs.diagnostics())
def test_hostile_diagnostics_in_cclog_top(batches):
    lines = bounded(_listen, batches)
    assert not isinstance(lines, ValueError), lines
    assert all(printable(line) == line for line in lines)  # no control character, no bidirectional override


# -- names -------------------------------------------------------------------------------------------------

def _names(name):
    results = [window_names.parse_piece(name), window_names.parse_piece(name, window_names.ANY_PREFIX),
               recovery.prefix_of(name), formats.by_extension(name)]
    if window_names.parse_piece(name, window_names.ANY_PREFIX) is not None:
        results += [window_names.window_key(name), window_names.file_order(name), window_names.split_number(name)]
    return results


@fuzz
@given(names=st.lists(fs.names(), min_size=1, max_size=5))
def test_hostile_file_names(names):
    with Root() as root:
        paths = []
        for name in names:
            bounded(_names, name)
            if name and '/' not in name and '\0' not in name and name not in ('.', '..') \
                    and len(name.encode('utf-8', 'surrogatepass')) <= 255:
                try:
                    paths.append(root.put(name, b''))
                except (UnicodeEncodeError, OSError):
                    continue
        listed = bounded(log_format.window_files, root.input, '')
        if paths and not isinstance(listed, ValueError):
            bounded(log_format.window_sets, paths)
            bounded(recovery.scan, root.input)


# -- what the fuzzing found (each once, as it was found) ---------------------------------------------------

def _with_index_version(data, chunk, version):
    """``data`` (a bag) with the ``ver`` of the index data records that follow chunk number ``chunk`` set."""
    records, seen = fs.parse_records(data, len(b'#ROSBAG V2.0\n')), -1
    for record in records:
        op = dict(record[0]).get(b'op')
        seen += op == b'\x05'
        if op == b'\x04' and seen == chunk:
            record[0] = [(n, fs._U32.pack(version) if n == b'ver' else v) for n, v in record[0]]
    return b'#ROSBAG V2.0\n' + b''.join(fs.record_bytes(fields, body) for fields, body in records)


@pytest.mark.parametrize('compression', ['none', 'bz2', 'lz4'])
def test_a_damaged_index_after_a_good_one_is_a_value_error(compression, tmp_path):
    """bag_reader read the index of the first chunk as views of the file's map; the second chunk's damaged
    index raised, and closing the map under those views turned the one-line ValueError into a BufferError
    traceback (``cannot close exported pointers exist``)."""
    data = dict(fs.valid_bags())['plain_%s.bag' % compression]
    path = str(tmp_path / 'damaged.bag')
    with open(path, 'wb') as stream:
        stream.write(_with_index_version(data, 1, 2))
    with pytest.raises(ValueError, match='damaged.bag: bag is truncated or damaged \\(index of the chunk at byte'):
        list(bag_reader.read_raw(path, BAG_TOPICS))


def _with_chunk_bytes_flipped(data, compression):
    """``data`` (a bag) with bytes 12 to 60 of its first chunk's data flipped (its header and sizes intact)."""
    records = fs.parse_records(data, len(b'#ROSBAG V2.0\n'))
    chunk = next(record for record in records if dict(record[0]).get(b'op') == b'\x05')
    assert dict(chunk[0])[b'compression'] == compression.encode()
    chunk[1] = chunk[1][:12] + bytes(b ^ 0xff for b in chunk[1][12:60]) + chunk[1][60:]
    return b'#ROSBAG V2.0\n' + b''.join(fs.record_bytes(fields, body) for fields, body in records)


@pytest.mark.parametrize('compression', ['bz2', 'lz4'])
def test_a_chunk_that_does_not_decompress_is_a_value_error_through_rosbag(compression, tmp_path):
    """Through rosbag (``bag_open.read_raw``: the reader of encrypted bags) a compressed chunk that does not
    decompress raised roslz4's or bz2's OSError, a traceback where every other damage is one line."""
    data = dict(fs.valid_bags())['plain_%s.bag' % compression]
    path = str(tmp_path / 'damaged.bag')
    with open(path, 'wb') as stream:
        stream.write(_with_chunk_bytes_flipped(data, compression))
    with pytest.raises(ValueError, match='damaged.bag: bag is truncated or damaged'):
        list(bag_open.read_raw(path, BAG_TOPICS))
    with pytest.raises(ValueError, match='damaged.bag: bag is truncated or damaged'):
        list(bag_reader.read_raw(path, BAG_TOPICS))


@pytest.mark.parametrize('value', [10 ** 400, -10 ** 400])
def test_max_windows_per_hour_of_an_integer_beyond_a_float_is_a_value_error(value):
    with pytest.raises(ValueError, match='max_windows_per_hour: .* is not a number'):
        options.get('max_windows_per_hour').parse(value)

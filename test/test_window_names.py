"""One naming scheme for a window's pieces (log_format: ``<name>[+<route>][.<NNN>]<ext>``): the name chosen once,
reserved in its directory for every piece; one parser (``parse_piece``) groups files by window for every reader,
old names still read; ``cclog replay`` and ``--sweep`` count windows, not files."""
import contextlib
import errno
import io
import json
import os

import pytest
import yaml

from cc_log import sim
from cc_log.logger import options
from cc_log.base.routes import parse_routes
from cc_log.triggers import base as triggers_base
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.offline import cli
from cc_log.storage import log_format

NAME = 'cc_log_20150521T191138.027Z_classifier'


@pytest.mark.parametrize('piece, expected', [
    (NAME + '.bag', (NAME, None, 0)),
    (NAME + '+numeric.json.xz', (NAME, 'numeric', 0)),
    (NAME + '.002.bag', (NAME, None, 2)),
    (NAME + '+numeric.002.json.xz', (NAME, 'numeric', 2)),
    (NAME + '_1.bag', (NAME + '_1', None, 0)),
    (NAME + '_1+numeric.003.json.xz', (NAME + '_1', 'numeric', 3)),
    (NAME + '.002_recovered.bag', (NAME, None, 2)),
    # names written before the scheme: read, never written
    (NAME + '_part2.json.xz', (NAME, None, 2)),
    (NAME + '_part2_1.json.xz', (NAME, None, 2)),
    (NAME + '+numeric_part3.json.xz', (NAME, 'numeric', 3)),
    (NAME + '+numeric_1.json.xz', (NAME, 'numeric', 0)),
    ('cc_log_20150521T191138.027Z_collect_part1.bag', ('cc_log_20150521T191138.027Z_collect', None, 1)),
])
def test_one_parser_reads_every_piece_name_new_and_old(piece, expected):
    assert tuple(log_format.parse_piece(piece)) == expected
    directory = os.path.join('logs', 'robot')
    assert log_format.window_key(os.path.join(directory, piece)) == os.path.join(directory, expected[0])


@pytest.mark.parametrize('name', [NAME + '.bag\n', NAME + '\n.bag', NAME + '+numeric\n.json.xz', NAME + '+a b.bag',
                                  'cc_log_context_20150521T191138.027Z.bag', 'x' + NAME + '.bag', NAME + '.bag.orig'])
def test_a_name_with_anything_more_is_no_window_piece(name):
    assert log_format.parse_piece(name) is None  # re.fullmatch: not even a trailing newline


def _route(name):
    return parse_routes([{'name': name, 'topics': ['/odom'], 'format': 'json-xz'}], ('json-xz',))


@pytest.mark.parametrize('check', [_route, triggers_base.check_name, options.check_label])
def test_every_name_check_refuses_a_trailing_newline(check):
    check('numeric')
    with pytest.raises(ValueError):  # re.match('^...$') let it through
        check('numeric\n')


def test_piece_names_are_what_the_parser_reads():
    for route in (None, 'numeric'):
        for number in (0, 1, 2, 1000):
            assert tuple(log_format.parse_piece(log_format.piece_name(NAME, route, number) + '.bag')) == (
                NAME, route, number)


def test_a_name_is_reserved_once_and_never_shared(tmp_path):
    directory = str(tmp_path)
    first, second = log_format.WindowName(NAME), log_format.WindowName(NAME)
    window = LogWindow([Record(1.0, '/odom', None, 1)], [Trigger(1.0, 'x', None, 'classifier')])
    assert first.take(directory, window) == NAME  # reserved (O_EXCL) before any piece exists
    assert second.take(directory, window) == NAME + '_1'
    first.release()
    with open(os.path.join(directory, NAME + '+numeric.json.xz.tmp-1'), 'wb'):
        pass  # a piece being written (or a crash's leftover) holds the name without its reservation
    third = log_format.WindowName(NAME)
    assert third.take(directory, window) == NAME + '_2'
    second.release()
    third.release()
    assert sorted(os.listdir(directory)) == [NAME + '+numeric.json.xz.tmp-1']  # no reservation left


def test_a_name_reserved_on_a_full_disk_is_the_empty_file_and_recovery_keeps_a_recent_one(tmp_path, monkeypatch):
    from cc_log.storage import recovery, window_names
    directory = str(tmp_path)

    def full(fd, data):
        raise OSError(errno.ENOSPC, 'No space left on device')
    monkeypatch.setattr(window_names.os, 'write', full)
    name, reservation = log_format.reserve_name(directory, NAME)
    monkeypatch.undo()
    assert name == NAME and os.path.getsize(reservation) == 0  # no error, nothing more reserved
    assert log_format.reservations(directory) == [(reservation, None)]
    assert recovery.release_stale_names(directory) == [] and os.path.exists(reservation)  # may be a writer's
    old = os.stat(reservation).st_mtime - recovery.BUSY_SECONDS - 1
    os.utime(reservation, (old, old))
    assert recovery.release_stale_names(directory) == [reservation] and not os.listdir(directory)


# -- end to end: cclog replay with a route -----------------------------------------------------------------

def _replay(bag, cfg, out, *more):
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert cli.main(['replay', bag, '--config', cfg, '--out', out, '--json'] + list(more)) == 0
    return json.loads(text.getvalue())


def _info(out):
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert cli.main(['info', out, '--json']) == 0
    return json.loads(text.getvalue())


@pytest.fixture(scope='module')
def simulated(tmp_path_factory):
    """A simulated run (scan, odometry, IMU) and the configuration of a window every 10 s with the numeric route
    (odometry and IMU as json-xz) beside the window's own bag; ``config(**windows)`` writes one."""
    folder = tmp_path_factory.mktemp('names')
    bag = str(folder / 'run.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(seed=3, minutes=0.5, anomalies=0, imu=True, camera=False, scan=True))

    def config(fmt='bag-lz4', **windows):
        path = folder / ('config-%s-%d.yaml' % (fmt, len(os.listdir(str(folder)))))
        path.write_text(yaml.safe_dump({
            'driving_topic': sim.ODOM_TOPIC, 'topics': ['*'], 'windows': dict({'pre': '2s', 'post': '2s'}, **windows),
            'format': fmt, 'routes': [{'name': 'numeric', 'topics': [sim.ODOM_TOPIC, sim.IMU_TOPIC],
                                       'format': 'json-xz'}],
            'triggers': [{'name': 'every10s', 'kind': 'periodic', 'every': '10s'}]}))
        return str(path)
    return bag, config


def test_two_replays_into_one_directory_keep_each_route_file_with_its_window(simulated, tmp_path):
    bag, config = simulated
    out, cfg = str(tmp_path / 'out'), config()
    _replay(bag, cfg, str(tmp_path / 'alone'))
    alone = _info(str(tmp_path / 'alone'))['total']['windows']
    first = _replay(bag, cfg, out)
    second = _replay(bag, cfg, out)  # the same windows again: the same first stamps and triggers
    info = _info(out)
    assert alone >= 2 and info['total']['windows'] == 2 * alone
    for window in info['windows']:  # each window: its bag and its own route file, /odom in every one
        assert [os.path.basename(path).endswith('+numeric.json.xz') for path in window['files']] == [False, True]
        assert window['topics'].get(sim.ODOM_TOPIC, 0) > 0 and sim.SCAN_TOPIC in window['topics']
        pieces = [log_format.parse_piece(os.path.basename(path)) for path in window['files']]
        assert len({piece.name for piece in pieces}) == 1 and pieces[1].route == 'numeric'
    odometry = [log_format.read_window_set(w['files'])[0]['counts'][sim.ODOM_TOPIC] for w in first['windows']]
    assert sorted(w['topics'][sim.ODOM_TOPIC] for w in info['windows']) == sorted(odometry * 2)
    names = [w['name'] for w in first['windows'] + second['windows']]
    assert len(set(names)) == len(names)  # the second replay's windows took names of their own (``_1``)
    assert not [name for name in os.listdir(out) if log_format.RESERVED_MARK in name]


def test_replay_counts_windows_not_files_with_routes_and_json_xz_parts(simulated, tmp_path):
    bag, config = simulated
    out = str(tmp_path / 'out')
    summary = _replay(bag, config('json-xz', max=150), out)  # parts of 150 odometry messages: a file per part
    files = log_format.window_files(out)
    sets = log_format.window_sets(files)
    assert len(summary['windows']) == len(sets)  # one entry per window, not per file
    assert len(files) > 2 * len(sets)  # each window: several parts, each with its route's file
    for window, files_of_one in zip(summary['windows'], sets):
        assert window['files'] == files_of_one and window['path'] == files_of_one[0]
        assert window['name'] == log_format.parse_piece(os.path.basename(files_of_one[0])).name
        metadata, records = log_format.read_window_set(files_of_one)
        assert window['messages'] == len(records) == metadata['count']
        assert window['start'] == pytest.approx(records[0].stamp, abs=1e-6)


def test_a_sweep_counts_windows_not_files_with_routes_and_json_xz_parts(simulated, tmp_path):
    from cc_log.logger import config
    from cc_log.offline import sweep
    bag, make = simulated
    cfg = config.Config.from_dict(yaml.safe_load(open(make('json-xz', max=150)).read()))
    out = str(tmp_path / 'sweep')
    row, = sweep.sweep_one(bag, out, [sweep.Sweep('routes', cfg, None)])['rows']
    files = log_format.window_files(os.path.join(out, 'routes'))
    starts = {os.path.basename(path)[len(log_format.PREFIX):].split('_')[0] for path in files}
    assert row['windows'] == len(starts)  # windows 10 s apart: one first stamp (UTC in the name) per window
    sets = log_format.window_sets(files)
    assert len(sets) == len(starts) and len(files) > 2 * len(sets)  # parts and route files: several per window
    assert row['kept'] == sum(log_format.read_window_set(files_of_one)[0]['count'] for files_of_one in sets)


def _played_twice(bag, config_path, out, **extra):
    """Replay's summary of ``bag`` fed twice into one offline logger writing into ``out`` (``rosbag play -l``),
    with the configuration at ``config_path`` and ``extra`` logger options."""
    from cc_log.logger import config
    from cc_log.offline import replay
    from cc_log.storage.bag import bagio
    cfg = config.Config.from_dict(yaml.safe_load(open(config_path).read()))
    opened = replay.open_bag(bag)
    try:
        options, _, topics = replay.replay_setup(cfg, opened)
    finally:
        opened.close()
    records = list(bagio.read_messages(bag, sorted(topics)))
    return replay.replay_records(replay.offline_logger(out, dict(options, **extra)), records + records)


def test_a_looping_bag_gives_each_window_its_own_name_and_route_file(simulated, tmp_path):
    """``rosbag play -l`` into one logger: the stamps come again, so do the names proposed; each window still
    gets a name of its own, its route file with it (/odom in every window)."""
    bag, make = simulated
    out = str(tmp_path / 'loop')
    summary = _played_twice(bag, make(), out)
    sets = log_format.window_sets(log_format.window_files(out))
    for files in sets:
        assert [os.path.basename(path).endswith('+numeric.json.xz') for path in files] == [False, True]
        metadata, _ = log_format.read_window_set(files)
        assert metadata['counts'].get(sim.ODOM_TOPIC, 0) > 0
    assert len(summary['windows']) == len(sets) >= 4


def test_a_prefix_names_every_piece_of_every_window_and_recovery_releases_its_reservations_only(simulated, tmp_path):
    """A logger's file prefix (``~name_prefix``) reaches the name reserved once per window: its json-xz parts, its
    route files and a looping bag's second windows (``_1``) all begin with it, no reservation is left; readers
    group a window's files whatever the prefix; recovery of that prefix removes its stale reservations only."""
    from cc_log.storage import recovery
    from test_reliability import DEAD_PID
    bag, make = simulated
    out, run = str(tmp_path / 'out'), log_format.file_prefix('run')
    summary = _played_twice(bag, make('json-xz', max=150), out, prefix=run)
    assert os.listdir(out) and all(name.startswith(run) and log_format.RESERVED_MARK not in name
                                   for name in os.listdir(out))
    files = log_format.window_files(out, run)
    sets = log_format.window_sets(files)
    assert sorted(w['files'] for w in summary['windows']) == sorted(sets) and len(sets) >= 4
    assert len(files) > 2 * len(sets) and log_format.window_files(out) == []  # parts and routes; no cc_log_ file
    for files_of_one in sets:
        pieces = [log_format.parse_piece(os.path.basename(path), run) for path in files_of_one]
        assert len({piece.name for piece in pieces}) == 1 and {piece.route for piece in pieces} == {None, 'numeric'}
        assert log_format.parse_piece(os.path.basename(files_of_one[0])) is None  # not a cc_log_ piece
        metadata, read = log_format.read_window_set(files_of_one)
        assert metadata['count'] == len(read) == sum(len(log_format.read_window(path)[1]) for path in files_of_one)
    names = [w['name'] for w in summary['windows']]
    assert len(set(names)) == len(names) and any(name.endswith('_1') for name in names)
    reserved = {}
    for prefix in (run, log_format.PREFIX):  # reservations of a process gone
        reserved[prefix] = os.path.join(out, prefix + '20150521T191138.027Z_x' + log_format.RESERVED_MARK)
        with open(reserved[prefix], 'w') as stream:
            stream.write('%d\n' % DEAD_PID)
    assert log_format.reservations(out, run) == [(reserved[run], DEAD_PID)]
    assert recovery.recover_directory(out, run) == []
    assert not os.path.exists(reserved[run]) and os.path.exists(reserved[log_format.PREFIX])

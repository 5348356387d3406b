"""No write follows a link, nothing cc_log creates is world-writable, a failed write leaves no descriptor open.

Every writer is attacked as a local user would: a symbolic link planted at the temporary name
(``<final>.tmp-<pid>``), at the final name, at ``<leftover>.reindex``; every writer runs under umask 0.
The ``cclog`` commands run as real processes (see test_cli.py).
"""
import json
import os
import stat
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from cc_log.learning import learning
from cc_log.base import safe_files
from cc_log.storage import log_format, recovery
from cc_log.features import FeatureConfig, vector_length
from cc_log.storage.log_format import Format, read_window, write_window

from test_cli import replayed, run, trained  # noqa: F401  (fixtures of the cclog runs)
from test_reliability import ROOT, crashing_writer, window

CONFIG = FeatureConfig('motion', '20')
VICTIM_TEXT = b'precious: must never change\n'


@pytest.fixture
def victim(tmp_path):
    """A file outside the logging directory that planted links point at; checked unchanged afterwards."""
    path = tmp_path / 'victim'
    path.write_bytes(VICTIM_TEXT)
    path.chmod(0o600)
    yield path
    assert path.read_bytes() == VICTIM_TEXT and stat.S_IMODE(path.stat().st_mode) == 0o600


def plant(link, victim):
    os.symlink(str(victim), str(link))
    return str(link)


def mode(path):
    return stat.S_IMODE(os.lstat(str(path)).st_mode)


# -- safe_files itself ------------------------------------------------------------------------------------

def test_create_refuses_a_link_or_a_file_at_the_name(tmp_path, victim):
    link = plant(tmp_path / 'new', victim)
    with pytest.raises(FileExistsError):
        safe_files.create(link)
    dangling = plant(tmp_path / 'dangling', tmp_path / 'nowhere')
    with pytest.raises(FileExistsError):
        safe_files.create(dangling)
    assert not (tmp_path / 'nowhere').exists()


def test_atomic_file_never_writes_through_a_planted_link(tmp_path, victim):
    final = tmp_path / 'out.txt'
    plant(str(final) + safe_files.TMP_MARK + str(os.getpid()), victim)
    with safe_files.AtomicFile(str(final)) as stream:
        stream.write(b'data')
    assert final.read_bytes() == b'data' and not final.is_symlink()
    # a link at the final name: without overwrite the next free name is taken, with overwrite it is replaced
    taken = tmp_path / 'taken.txt'
    plant(taken, victim)
    target = safe_files.AtomicFile(str(taken), names=[str(taken), str(tmp_path / 'taken_1.txt')])
    with target as stream:
        stream.write(b'next')
    assert target.path == str(tmp_path / 'taken_1.txt') and taken.is_symlink()
    with safe_files.AtomicFile(str(taken), overwrite=True) as stream:
        stream.write(b'replaced')
    assert not taken.is_symlink() and taken.read_bytes() == b'replaced'


def test_atomic_file_failing_leaves_nothing_and_closes_everything(tmp_path):
    before = set(os.listdir('/proc/self/fd'))
    with pytest.raises(KeyError):
        with safe_files.AtomicFile(str(tmp_path / 'x')) as stream:
            stream.write(b'half')
            raise KeyError('boom')
    assert os.listdir(str(tmp_path)) == [] and set(os.listdir('/proc/self/fd')) <= before


def test_make_dirs_sets_every_new_directory_2775_and_leaves_existing_ones(tmp_path):
    existing = tmp_path / 'existing'
    existing.mkdir()
    existing.chmod(0o700)
    old = os.umask(0)
    try:
        safe_files.make_dirs(str(existing / 'a' / 'b' / 'c'))
    finally:
        os.umask(old)
    for folder in ('a', 'a/b', 'a/b/c'):
        assert mode(existing / folder) == 0o2775, (folder, oct(mode(existing / folder)))
    assert mode(existing) == 0o700
    (tmp_path / 'file').write_text('x')
    with pytest.raises(OSError):
        safe_files.make_dirs(str(tmp_path / 'file' / 'sub'))


# -- every writer: a link at its temporary or final name ------------------------------------------------

@pytest.mark.parametrize('fmt', Format.ALL)
def test_window_writer_never_follows_a_link_at_its_temporary_or_final_name(fmt, tmp_path, victim):
    directory = tmp_path / 'logs'
    directory.mkdir()
    win = window()
    final = str(directory / (log_format.base_name(win) + Format.EXTENSIONS[fmt]))
    plant(final + log_format.TMP_MARK + str(os.getpid()), victim)
    plant(final, victim)
    path, _ = write_window(win, str(directory), fmt)
    assert path != final and not os.path.islink(path) and mode(path) & 0o002 == 0
    assert len(read_window(path)[1]) == len(win.records)
    # the planted link is no leftover to recover: reported, left alone
    outcome, = recovery.recover_directory(str(directory))
    assert outcome.status == recovery.UNRECOVERABLE and 'not a regular file' in outcome.detail
    assert os.path.islink(outcome.leftover)


def test_vector_and_model_writers_replace_a_link_never_write_through_it(tmp_path, victim):
    from cc_log.learning.model import AnomalyModel
    vector = tmp_path / 'features' / 'nominal' / ('%.6f.json' % 12.5)
    vector.parent.mkdir(parents=True)
    plant(str(vector) + safe_files.TMP_MARK + str(os.getpid()), victim)
    plant(vector, victim)
    assert learning.write_vector(str(tmp_path / 'features'), 'nominal', 12.5, [1.0, 2.0], CONFIG) == str(vector)
    assert not vector.is_symlink() and json.loads(vector.read_text())['features'] == [1.0, 2.0]
    model, _ = learning.train(np.random.RandomState(0).normal(size=(40, vector_length(CONFIG))), None, CONFIG)
    path = tmp_path / 'model.json'
    plant(str(path) + safe_files.TMP_MARK + str(os.getpid()), victim)
    plant(path, victim)
    model.save(str(path))
    assert not path.is_symlink() and AnomalyModel.load(str(path)).threshold == model.threshold


def test_recover_never_writes_through_a_reindex_link_nor_lists_it(tmp_path, victim):
    directory = str(tmp_path / 'logs')
    os.makedirs(directory)
    crashing_writer(directory, messages=3000)
    leftover, = recovery.scan(directory)
    plant(leftover + '.reindex', victim)
    outcomes = recovery.recover_directory(directory)
    assert [o.leftover for o in outcomes] == [leftover] and outcomes[0].status == recovery.PARTIAL
    assert recovery.scan(directory) == [] and os.path.islink(leftover + '.reindex')


# -- descriptors --------------------------------------------------------------------------------------------

FAILING_WRITER = textwrap.dedent('''
    import json, os, resource, signal, sys
    sys.path.insert(0, {test!r})
    from test_reliability import window
    from cc_log.storage import log_format
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
    resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
    def descriptors():
        found = {{}}
        for fd in os.listdir('/proc/self/fd'):
            try:
                found[fd] = os.readlink('/proc/self/fd/' + fd)
            except FileNotFoundError:  # the descriptor of the listing itself
                pass
        return found
    before = descriptors()
    try:
        log_format.write_window(window(6000), {directory!r}, {fmt!r})
        error = None
    except OSError as failure:
        error = failure.errno
    after = descriptors()
    print(json.dumps({{'error': error, 'new': [after[fd] for fd in after if fd not in before]}}))
''')


@pytest.mark.parametrize('fmt, limit', [(Format.BAG_LZ4, 100000), (Format.JSON_XZ, 5000)])
def test_a_failed_write_closes_its_descriptor_and_removes_its_file(fmt, limit, tmp_path):
    import errno
    directory = str(tmp_path / 'logs')
    os.makedirs(directory)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [os.path.join(ROOT, 'src'),
                                                                    os.environ.get('PYTHONPATH')])))
    out = subprocess.run([sys.executable, '-c', FAILING_WRITER.format(
        test=os.path.join(ROOT, 'test'), directory=directory, fmt=fmt, limit=limit)], env=env,
        stdout=subprocess.PIPE, check=True, timeout=120).stdout
    result = json.loads(out.decode().strip().splitlines()[-1])
    assert result['error'] == errno.EFBIG
    assert result['new'] == []
    assert os.listdir(directory) == []


# -- permissions under umask 0 ------------------------------------------------------------------------------

def _file_ok(path):
    assert mode(path) == safe_files.FILE_MODE, (str(path), oct(mode(path)))


def _dir_ok(path):
    assert mode(path) == safe_files.DIR_MODE, (str(path), oct(mode(path)))


def test_library_writers_under_umask_0(tmp_path):
    from cc_log.storage.directory import LoggingDirectory
    old = os.umask(0)
    try:
        chosen = LoggingDirectory(str(tmp_path / 'robot' / 'ros' / 'logs'))
        paths = [write_window(window(), chosen.path, fmt)[0] for fmt in Format.ALL]
        vector = learning.write_vector(str(tmp_path / 'v' / 'features'), 'nominal', 1.0, [1.0], CONFIG)
        model, _ = learning.train(np.random.RandomState(0).normal(size=(40, vector_length(CONFIG))), None, CONFIG)
        saved = model.save(str(tmp_path / 'model.json'))
    finally:
        os.umask(old)
    for folder in ('robot', 'robot/ros', 'robot/ros/logs', 'v', 'v/features', 'v/features/nominal'):
        _dir_ok(tmp_path / folder)
    for path in paths + [vector, saved]:
        _file_ok(path)


def _umask_0():
    os.umask(0)


def test_cclog_outputs_under_umask_0_and_through_no_link(trained, replayed, real_bag, tmp_path, victim):  # noqa: F811
    out = tmp_path / 'new' / 'deeper'
    for name in ('odom.jsonl', 'run.png', 'all.bag'):
        plant(tmp_path / name, victim)  # an existing link at --out is replaced, never written through
    commands = [
        ('replay', replayed['bag'], '--topic', '/odom', '--model', trained['model'], '--out', out / 'logs',
         '--format', 'bag-lz4'),
        ('collect', replayed['bag'], '--topic', '/odom', '--out', out / 'vectors', '--window', '20'),
        ('learn', '--train', trained['train'], '--model', tmp_path / 'model.json'),
        ('export', replayed['out'], '--to', 'jsonl', '--out', tmp_path / 'odom.jsonl'),
        ('export', replayed['out'], '--to', 'csv', '--out', out / 'csv'),
        ('export', replayed['out'], '--to', 'bag', '--out', tmp_path / 'all.bag', '--force'),
        ('plot', replayed['out'], '--out', tmp_path / 'run.png'),
        ('simulate', '--minutes', '0.2', '--rate', '20', '--anomalies', '0', out / 'sim.bag'),
    ]
    for command in commands:
        result = run(*(command + ('--json',)), preexec_fn=_umask_0)
        assert result.returncode == 0, (command, result.stderr)
    for folder in ('new', 'new/deeper', 'new/deeper/logs', 'new/deeper/vectors', 'new/deeper/vectors/nominal',
                   'new/deeper/csv'):
        _dir_ok(tmp_path / folder)
    files = [tmp_path / name for name in ('model.json', 'odom.jsonl', 'all.bag', 'run.png')]
    files += [out / 'sim.bag', out / 'sim.bag.truth.json']
    for folder in ('logs', 'vectors/nominal', 'csv'):
        files += [path for path in (out / folder).iterdir()]
    assert len(files) > 10
    for path in files:
        assert not path.is_symlink()
        _file_ok(path)
    assert (tmp_path / 'run.png').read_bytes()[:4] == b'\x89PNG'


@pytest.mark.parametrize('umask, world', [(0o022, 0o005), (0o077, 0o000)])
def test_group_writable_whatever_the_umask(tmp_path, umask, world):
    """Directories 2775 and files 0664 as BWI's logger under umask 002, whatever the umask (it may only take
    the world bits)."""
    from cc_log.storage.directory import LoggingDirectory
    old = os.umask(umask)
    try:
        chosen = LoggingDirectory(str(tmp_path / 'robot' / 'logs'))
        paths = [write_window(window(), chosen.path, fmt)[0] for fmt in Format.ALL]
        vector = learning.write_vector(str(tmp_path / 'v'), 'nominal', 1.0, [1.0], CONFIG)
    finally:
        os.umask(old)
    for folder in ('robot', 'robot/logs', 'v', 'v/nominal'):
        assert mode(tmp_path / folder) == 0o2770 | world, (folder, oct(mode(tmp_path / folder)))
    for path in paths + [vector]:
        assert mode(path) == 0o660 | (world & 0o004), (path, oct(mode(path)))


@pytest.mark.parametrize('text, pid', [
    ('4242', 4242), (b' 4242\n', 4242), (str(safe_files.PID_MAX), safe_files.PID_MAX),
    (str(safe_files.PID_MAX + 1), None), ('0', None), ('000', None), ('', None), ('9' * 20, None), ('-1', None),
    ('\u0663', None), (b'\xff', None)])
def test_a_pid_is_read_by_one_parser_with_a_range(text, pid):
    """Issue 42 item 5: the pid of a leftover's name or a reservation: None when it names no process."""
    assert safe_files.pid_of(text) == pid
    assert not safe_files.writer_running(None)

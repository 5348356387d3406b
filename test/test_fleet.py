"""``cclog collect``, ``learn`` and ``replay`` over many bags on a real ``dask.distributed.LocalCluster`` (2 worker
processes, reached with ``--scheduler``): the vector files, the model and the window files equal those of the
one-process path (``--workers 0``); a damaged bag is one line naming it and the other bags' results stay."""
import filecmp
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from cc_log.offline import fleet, partition_learning, sweep
from cc_log.learning import learning
from cc_log.storage import log_format

distributed = pytest.importorskip('distributed')

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CCLOG = os.path.join(ROOT, 'scripts', 'cclog')
WINDOW = ('--topic', '/odom', '--window', '100', '--stride', '5')


def environment():
    env = dict(os.environ, ROS_MASTER_URI='http://127.0.0.1:1')
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [os.path.join(ROOT, 'src'), env.get('PYTHONPATH')]))
    return env


def cclog(*args):
    return subprocess.run([sys.executable, CCLOG] + [str(a) for a in args], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, universal_newlines=True, env=environment(), timeout=300)


def ok_json(*args):
    result = cclog(*(args + ('--json',)))
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


@pytest.fixture(scope='module')
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=':0',
                                  scheduler_kwargs={'dashboard': False}) as c:
        yield c.scheduler_address


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Two nominal runs (robot1, robot2, both named run.bag) and one with anomalies, one minute each."""
    root = tmp_path_factory.mktemp('fleet')
    for robot, seed, anomalies in (('robot1', 1, 0), ('robot2', 2, 0), ('robot3', 3, 1)):
        os.makedirs(str(root / 'bags' / robot))
        result = cclog('simulate', '--minutes', 1, '--anomalies', anomalies, '--seed', seed,
                       root / 'bags' / robot / 'run.bag')
        assert result.returncode == 0, result.stderr
    return root


def same_tree(a, b):
    """Same file names below ``a`` and ``b``, with the same bytes."""
    names = [sorted(os.path.relpath(os.path.join(d, f), a) for d, _, fs in os.walk(a) for f in fs)]
    names.append(sorted(os.path.relpath(os.path.join(d, f), b) for d, _, fs in os.walk(b) for f in fs))
    assert names[0] == names[1]
    match, mismatch, errors = filecmp.cmpfiles(a, b, names[0], shallow=False)
    assert not mismatch and not errors
    return names[0]


def model_arrays(path):
    with open(path) as stream:
        document = json.load(stream)
    document.pop('info')  # training seconds, memory and the engine differ; everything else may not
    return document


@pytest.fixture(scope='module')
def collected(bags, cluster):
    nominal = [bags / 'bags' / 'robot1' / 'run.bag', bags / 'bags' / 'robot2' / 'run.bag']
    one = ok_json('collect', *nominal, '--out', bags / 'one', '--workers', 0, *WINDOW)
    dask = ok_json('collect', *nominal, '--out', bags / 'dask', '--scheduler', cluster, *WINDOW)
    return bags, one, dask


def test_collect_on_the_cluster_writes_the_same_vector_files(collected):
    root, one, dask = collected
    names = same_tree(str(root / 'one'), str(root / 'dask'))
    assert one['vectors'] == dask['vectors'] == len(names) > 1000
    assert [row['directory'] for row in dask['bags']] == [str(root / 'dask' / 'robot1__run'),
                                                          str(root / 'dask' / 'robot2__run')]
    assert dask['failed'] == 0 and dask['messages'] == 12000 and 'scheduler' in dask['engine']


def test_learn_on_the_cluster_gives_the_same_model(collected, cluster):
    root = collected[0]
    ok_json('learn', '--train', root / 'one', '--model', root / 'one.json', '--workers', 0)
    ok_json('learn', '--train', root / 'dask', '--model', root / 'dask.json', '--scheduler', cluster)
    assert model_arrays(str(root / 'one.json')) == model_arrays(str(root / 'dask.json'))


@pytest.fixture(scope='module')
def replayed(collected, cluster):
    root = collected[0]
    ok_json('learn', '--train', root / 'one', '--model', root / 'model.json', '--workers', 0)
    args = (root / 'bags', '--topic', '/odom', '--model', root / 'model.json')
    one = ok_json('replay', *args, '--out', root / 'logs-one', '--workers', 0)
    dask = ok_json('replay', *args, '--out', root / 'logs-dask', '--scheduler', cluster)
    return root, one, dask


def test_replay_on_the_cluster_writes_the_same_windows(replayed):
    root, one, dask = replayed
    names = same_tree(str(root / 'logs-one'), str(root / 'logs-dask'))
    assert one['windows'] == dask['windows'] == len(names) > 0
    assert [len(row['windows']) for row in dask['bags']] == [len(row['windows']) for row in one['bags']]
    assert dask['bags'][2]['windows'], 'the run with anomalies has windows'
    assert dask['messages'] == one['messages'] == 18000


def test_sweep_reads_each_bag_once_for_every_configuration(replayed, cluster):
    root = replayed[0]
    with open(str(root / 'model.json')) as stream:
        threshold = repr(json.load(stream)['threshold'])
    document = ok_json('replay', root / 'bags', '--topic', '/odom', '--model', root / 'model.json', '--out',
                       root / 'sweep', '--scheduler', cluster, '--sweep', 'threshold=%s,-1e9' % threshold)
    same, never = document['configurations']
    assert same['label'] == 'threshold=%s' % threshold
    # the model's own threshold: the windows of the plain replay, file for file
    for robot in ('robot1', 'robot2', 'robot3'):
        same_tree(str(root / 'logs-one' / robot), str(root / 'sweep' / robot / same['label']))
    assert same['windows'] == replayed[1]['windows'] > 0
    assert same['recall'] == 1.0 and same['false_per_hour'] >= 0
    assert never['windows'] == never['kept'] == 0 and never['recall'] == 0.0
    assert same['messages'] == never['messages'] == 18000


def test_streamed_learning_holds_one_partition_at_a_time_and_flags_few_held_out(collected, cluster):
    root = collected[0]
    document = ok_json('learn', '--train', root / 'dask', '--model', root / 'stream.json', '--method', 'stream',
                       '--scheduler', cluster)
    info = document['info']
    assert info['method'] == 'nystroem-sgd-streamed' and info['partitions'] == 2
    assert info['held_out_flagged'] <= 0.02 * info['vectors_held_out']
    with open(str(root / 'stream.json')) as stream:
        assert json.load(stream)['kind'] == 'nystroem-sgd'


def test_a_damaged_bag_is_one_line_and_the_others_are_kept(collected, cluster):
    root = collected[0]
    damaged = root / 'damaged.bag'
    with open(str(root / 'bags' / 'robot1' / 'run.bag'), 'rb') as stream:
        damaged.write_bytes(stream.read()[:5000])
    good = root / 'bags' / 'robot2' / 'run.bag'
    result = cclog('collect', damaged, good, '--out', root / 'partial', '--scheduler', cluster, '--json', *WINDOW)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('cclog collect: error: %s: ' % damaged), result.stderr
    rows = json.loads(result.stdout)['bags']
    assert 'error' in rows[0] and rows[1]['vectors'] > 0
    assert rows[1]['directory'] == str(root / 'partial' / 'bags__robot2__run')
    assert len(os.listdir(os.path.join(rows[1]['directory'], 'nominal'))) == rows[1]['vectors']


def test_inputs_expand_to_bags_and_distinct_output_names(tmp_path):
    for name in ('a/run.bag', 'b/run.bag', 'b/c/x.bag', 'b/notes.txt'):
        os.makedirs(str((tmp_path / name).parent), exist_ok=True)
        (tmp_path / name).write_bytes(b'')
    found = fleet.expand_bags([str(tmp_path / 'a'), str(tmp_path / 'b'), str(tmp_path / '*' / 'run.bag')])
    assert [os.path.relpath(p, str(tmp_path)) for p in found] == ['a/run.bag', 'b/c/x.bag', 'b/run.bag']
    assert fleet.output_names(found) == ['a__run', 'b__c__x', 'b__run']
    with pytest.raises(ValueError, match='nothing.bag: no such bag'):
        fleet.expand_bags([str(tmp_path / 'nothing.bag')])
    os.makedirs(str(tmp_path / 'empty'))
    with pytest.raises(ValueError, match='empty: no \\*.bag file'):
        fleet.expand_bags([str(tmp_path / 'empty')])


def test_workers_and_scheduler_exclude_each_other_and_dask_is_installed_by_dev_sh():
    result = cclog('collect', 'x.bag', '--out', 'o', '--topic', '/odom', '--workers', 1, '--scheduler', 'tcp://x:1')
    assert result.returncode == 2 and 'not allowed with argument' in result.stderr
    listed = subprocess.run(['bash', os.path.join(ROOT, 'dev.sh'), 'packages'], stdout=subprocess.PIPE,
                            universal_newlines=True, timeout=60).stdout.split()
    assert {'python3-dask', 'python3-distributed'} <= set(listed)


def test_sweep_values_make_every_combination_and_bad_keys_are_one_line():
    combinations = sweep.parse_sweep(['threshold=0,0.1', 'pre=100,2s,5s'])
    assert len(combinations) == 6
    assert sweep.sweep_label(combinations[1]) == 'threshold=0,pre=2s'
    for bad, text in (('nu=0.1', 'expected KEY=V1,V2'), ('pre', 'expected KEY=V1,V2'), ('pre=', 'pre: no value')):
        with pytest.raises(ValueError, match=text):
            sweep.parse_sweep([bad])
    with pytest.raises(ValueError, match='pre is given twice'):
        sweep.parse_sweep(['pre=1', 'pre=2'])


def test_whole_partitions_are_held_out_from_five_on():
    assert partition_learning.partition_roles(4, 0.2) == ['split'] * 4
    roles = partition_learning.partition_roles(40, 0.2)
    assert roles.count('held') == 8 and roles[0] == 'train' and roles[-1] == 'train'


def test_paths_that_would_share_an_output_name_get_distinct_ones():
    names = fleet.output_names(['/d/a/b/run.bag', '/d/a__b/run.bag', '/d/a/run', '/d/a/run.bag', '/d/c/x.bag'])
    assert len(set(names)) == 5
    assert names[0].startswith('a__b__run-') and names[1].startswith('a__b__run-') and names[4] == 'c__x'
    assert names[2].startswith('a__run-') and names[3].startswith('a__run-')
    # a name does not depend on the other inputs' order
    assert fleet.output_names(['/d/a__b/run.bag', '/d/a/b/run.bag'])[::-1] == names[:2]


def started(*args):
    """``cclog ARGS`` running in its own process group (as from a terminal, whose Ctrl-C reaches every process)."""
    return subprocess.Popen([sys.executable, CCLOG] + [str(a) for a in args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, universal_newlines=True, env=environment(),
                            start_new_session=True)


def wait_for(condition, process, what, timeout=120):
    deadline = time.monotonic() + timeout
    while not condition():
        assert process.poll() is None, 'cclog ended before %s: %s' % (what, process.communicate())
        assert time.monotonic() < deadline, 'no %s within %d s' % (what, timeout)
        time.sleep(0.02)


def ended_pid():
    child = subprocess.Popen(['true'])
    child.wait()
    return child.pid


def test_a_cancelled_collect_leaves_no_half_written_vector_file(collected):
    """Ctrl-C of a collect on a local cluster: the vector files a worker left half written (``*.tmp-<pid>`` of
    an ended process; one planted, as a killed worker leaves it) are removed, a running process's are kept,
    and every vector file left is whole; learning never counts a leftover."""
    root = collected[0]
    out = root / 'cancelled'
    bags = [root / 'bags' / robot / 'run.bag' for robot in ('robot1', 'robot2', 'robot3')]
    folder = out / 'robot3__run' / 'nominal'
    os.makedirs(str(folder))
    dead = folder / ('1600000000.000000.json%s%d' % (log_format.TMP_MARK, ended_pid()))
    live = folder / ('1600000000.010000.json%s%d.1' % (log_format.TMP_MARK, os.getpid()))
    for leftover in (dead, live):
        leftover.write_text('{"stamp": 1600000000.0, "feat')
    assert not fleet.holds_vectors(str(folder.parent))  # a leftover alone is no vector directory
    process = started('collect', *bags, '--out', out, '--workers', 1, '--topic', '/odom', '--window', '100',
                      '--stride', '1')
    wait_for(lambda: any(name.endswith('.json') for _, _, names in os.walk(str(out)) for name in names),
             process, 'vector file')
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130 and 'cclog collect: interrupted' in stderr, stderr
    leftovers = [name for _, _, names in os.walk(str(out)) for name in names if log_format.TMP_MARK in name]
    assert leftovers == [live.name]
    for directory in fleet.expand_vector_dirs([str(out)]):
        vectors, _ = learning.load_vectors(directory)  # every file whole (a partial one is a ValueError)
        assert sum(len(v) for v in vectors.values()) == len(os.listdir(os.path.join(directory, 'nominal'))) - (
            1 if directory.endswith('robot3__run') else 0)


def test_ctrl_c_stops_a_replay_in_this_process_within_a_second(tmp_path):
    """``cclog replay --workers 0`` with a window open over the whole run (a model that flags everything):
    Ctrl-C stops it within about a second (it took 18 s: the open window was written first, then the
    interpreter freed the buffer), and what is under a final name is a whole window."""
    bag = tmp_path / 'run.bag'
    result = cclog('simulate', '--minutes', 6, '--anomalies', 0, '--seed', 5, '--imu', bag)
    assert result.returncode == 0, result.stderr
    assert cclog('collect', bag, '--out', tmp_path / 'vectors', *WINDOW).returncode == 0
    assert cclog('learn', '--train', tmp_path / 'vectors', '--model', tmp_path / 'model.json').returncode == 0
    with open(str(tmp_path / 'model.json')) as stream:
        model = json.load(stream)
    model['threshold'] = 1e9  # every classification triggers: one window, open to the end
    (tmp_path / 'hot.json').write_text(json.dumps(model))
    out = tmp_path / 'windows'
    process = started('replay', bag, '--topic', '/odom', '--side-topic', '/imu/data', '--model',
                      tmp_path / 'hot.json', '--out', out, '--workers', 0, '--format', 'json-xz')
    # well into the run: the process has spent 2 s of CPU since its output directory appeared (of ~5 s)
    wait_for(lambda: os.path.isdir(str(out / 'run')), process, 'output directory')
    begun = cpu_seconds(process.pid)
    wait_for(lambda: cpu_seconds(process.pid) > begun + 2, process, '2 CPU seconds of replay')
    interrupted = time.monotonic()
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    seconds = time.monotonic() - interrupted
    assert process.returncode == 130 and stderr.strip().endswith('cclog replay: interrupted'), stderr
    assert seconds < 3.0, 'Ctrl-C took %.1f s' % seconds
    for path in log_format.window_files(str(out / 'run')):  # final names (leftovers: .tmp-, .reserved)
        log_format.read_window(path)


def cpu_seconds(pid):
    """User + system CPU seconds of a running process (/proc/<pid>/stat)."""
    with open('/proc/%d/stat' % pid) as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / float(os.sysconf('SC_CLK_TCK'))


def test_a_fleet_replay_learning_online_learns_from_each_bag_alone(replayed, cluster):
    """With learn_online every bag learns on its own, its refit in its own directory (nothing beside the model
    shared by parallel workers, nothing resumed): one process and the cluster keep the same windows."""
    root = replayed[0]
    config = root / 'learn.yaml'
    config.write_text('triggers:\n  - {name: classifier, kind: classifier, learn_online: true, learn_every: 100, '
                      'learn_guard: 1s}\n')
    args = (root / 'bags', '--topic', '/odom', '--model', root / 'model.json', '--config', config)
    one = ok_json('replay', *args, '--out', root / 'learn-one', '--workers', 0)
    dask = ok_json('replay', *args, '--out', root / 'learn-dask', '--scheduler', cluster)
    assert not os.path.exists(str(root / 'model.online.json'))
    for out, result in (('learn-one', one), ('learn-dask', dask)):
        assert result['failed'] == 0
        for name in ('robot1__run', 'robot2__run', 'robot3__run'):
            assert os.path.exists(str(root / out / name / 'model.online.json')), (out, name)
    assert [len(row['windows']) for row in one['bags']] == [len(row['windows']) for row in dask['bags']]
    assert [row['online'] for row in one['bags']] == [[{'classifier': 'classifier', 'resumed': None}]] * 3

"""``cclog``, the offline tool, run as users and evaluation scripts run it: the real ``scripts/cclog`` in a
subprocess (``/usr/bin/python3``, list arguments, no shell) on the real bags of ../shared/data/real/.

No roscore: every run gets ROS_MASTER_URI pointing at a closed port, so a command that needed a master
would hang or fail. Checked: exit codes, the one-line error for every kind of bad input, the ``--json``
fields (against what the bags and the written files really hold), and that progress bars stay on stderr.
"""
import io
import json
import os
import shutil
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CCLOG = os.path.join(ROOT, 'scripts', 'cclog')
COMMANDS = ('collect', 'learn', 'replay', 'info', 'cat', 'export', 'codecs', 'plot', 'simulate')

HUSKY = 'husky_outdoor_2015.bag'
HUSKY_ODOM = '/husky_velocity_controller/odom'
NORMAL = 'sequor_E2_normal_safe_escape_straight.bag'
JERKY = 'sequor_N2_anomalous_jerky_driving.bag'
ALFA = 'alfa_carbonZ_engine_failure.bag'
WINDOW = '20'  # feature window of the Sequor model: the normal runs are 20 trials of ~23 messages


def run(*args, **kwargs):
    """Run ``cclog ARGS``; return the CompletedProcess (text stdout/stderr)."""
    env = dict(os.environ)
    env['ROS_MASTER_URI'] = 'http://127.0.0.1:1'  # nothing listens: offline commands must not need it
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [env.get('PYTHONPATH'), os.path.join(ROOT, 'src')]))
    env.pop('COLUMNS', None)
    result = subprocess.run([sys.executable, CCLOG] + [str(arg) for arg in args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, timeout=300, **kwargs)
    # decoded by hand: text mode would turn the progress bar's carriage returns into newlines
    result.stdout, result.stderr = result.stdout.decode('utf-8'), result.stderr.decode('utf-8')
    return result


def ok(*args):
    """Run ``cclog ARGS``, assert success and return stdout."""
    result = run(*args)
    assert result.returncode == 0, 'cclog %s failed (%d): %s' % (' '.join(map(str, args)), result.returncode,
                                                                 result.stderr)
    return result.stdout


def ok_json(*args):
    """Run ``cclog ARGS --json``; stdout must be exactly one JSON object."""
    out = ok(*(args + ('--json',)))
    assert out.count('\n') == 1 and out.endswith('\n'), out
    document = json.loads(out)
    assert isinstance(document, dict)
    return document


def fails(*args, **kwargs):
    """Run ``cclog ARGS``; assert it fails with one line ``cclog <command>: error: ...``; return that line."""
    status = kwargs.pop('status', 1)
    result = run(*args)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == status, (result.returncode, result.stderr)
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith('cclog %s: error: ' % args[0]), lines[0]
    assert result.stdout == ''
    return lines[0]


def bag_messages(path, topics):
    """Records of ``topics`` read straight with rosbag: (stamp, topic, msg), stamp as cc_log defines it."""
    import rosbag
    from cc_log.features import stamp_of
    with rosbag.Bag(path) as bag:
        return [(stamp_of(msg, t.to_sec()), topic, msg) for topic, msg, t in bag.read_messages(topics=topics)]


# -- a trained model and a replay, shared by the tests of one session -----------------------------------------

_CACHE = {}


@pytest.fixture
def trained(real_bag, tmp_path_factory):
    """Vectors of the normal Sequor runs (collect), a model trained on them alone (learn)."""
    if 'trained' not in _CACHE:
        base = tmp_path_factory.mktemp('trained')
        normal = real_bag(NORMAL)
        collect = ok_json('collect', normal, '--topic', '/odom', '--out', base / 'train', '--window', WINDOW,
                          '--stride', '1')
        model = base / 'model.json'
        learn = ok_json('learn', '--train', base / 'train', '--model', model)
        _CACHE['trained'] = {'dir': base, 'train': base / 'train', 'model': model, 'collect': collect,
                             'learn': learn}
    return _CACHE['trained']


@pytest.fixture
def replayed(trained, real_bag, tmp_path_factory):
    """``cclog replay --json`` of the jerky-driving bag with the normal-driving model, /scan kept too."""
    if 'replayed' not in _CACHE:
        out = tmp_path_factory.mktemp('replay') / 'logs'
        bag = real_bag(JERKY)
        summary = ok_json('replay', bag, '--topic', '/odom', '--side-topic', '/scan', '--model', trained['model'],
                          '--out', out, '--pre', '10', '--post', '10')
        _CACHE['replayed'] = {'bag': bag, 'out': out, 'summary': summary}
    return _CACHE['replayed']


# -- help -----------------------------------------------------------------------------------------------------

def test_help_lists_every_command_with_examples():
    out = ok('--help')
    for command in COMMANDS:
        assert '\n    %s ' % command in out, command
    assert 'examples:' in out


@pytest.mark.parametrize('command', COMMANDS)
def test_every_command_has_help_with_examples(command):
    out = ok(command, '--help')
    assert out.startswith('usage: cclog %s' % command)
    examples = out.split('examples:\n', 1)[1]
    assert '  cclog %s ' % command in examples
    assert '--progress' in out


def test_no_command_and_unknown_command_are_usage_errors():
    result = run()
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    result = run('bogus')
    assert result.returncode == 2
    assert "invalid choice: 'bogus'" in result.stderr and len(result.stderr.strip().splitlines()) == 1


# -- collect and learn ----------------------------------------------------------------------------------------

def test_collect_writes_one_vector_file_per_vector_under_the_label(trained):
    collect = trained['collect']
    folder = trained['train'] / 'nominal'
    assert collect['directory'] == str(folder)
    assert collect['label'] == 'nominal' and collect['window'] == WINDOW and collect['stride'] == 1
    files = sorted(os.listdir(folder))
    assert collect['vectors'] == len(files) > 20
    document = json.loads((folder / files[0]).read_text())
    assert document['config'] == {'feature_set': 'motion', 'window': WINDOW, 'topic_type': 'nav_msgs/Odometry'}


def test_without_topic_the_bags_only_odometry_topic_drives_and_is_said(real_bag, tmp_path):
    """A newcomer's bag: odometry on /husky_velocity_controller/odom, no --topic: collect and replay take the bag's
    only topic of the feature set's (the model's) type, saying which in one line; two such topics: one-line error
    naming both."""
    husky = real_bag(HUSKY)
    result = run('collect', husky, '--out', tmp_path / 'vectors', '--window', '5s', '--json')
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['topic'] == HUSKY_ODOM
    assert result.stderr.splitlines() == ["cclog collect: driving topic %s (the bag's only nav_msgs/Odometry topic; "
                                          "--topic chooses another)" % HUSKY_ODOM]
    ok('learn', '--train', tmp_path / 'vectors', '--model', tmp_path / 'model.json')
    result = run('replay', husky, '--model', tmp_path / 'model.json', '--out', tmp_path / 'logs', '--json')
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['windows'] and 'driving topic %s' % HUSKY_ODOM in result.stderr
    import rosbag
    two = str(tmp_path / 'two.bag')
    with rosbag.Bag(husky) as source, rosbag.Bag(two, 'w') as out:
        for topic, msg, t in source.read_messages(topics=[HUSKY_ODOM]):
            out.write(topic, msg, t)
            out.write('/odom', msg, t)
    line = fails('replay', two, '--model', tmp_path / 'model.json', '--out', tmp_path / 'two')
    assert '2 topics carry nav_msgs/Odometry (%s, /odom): give --topic' % HUSKY_ODOM in line, line
    line = fails('collect', real_bag(NORMAL).replace(NORMAL, 'f1tenth_DS1.bag'), '--features', 'imu',
                 '--out', tmp_path / 'imu')
    assert 'no topic carries sensor_msgs/Imu; its topics: /odom (nav_msgs/Odometry)' in line, line


def test_collect_label_and_duration_window(real_bag, tmp_path):
    out = ok('collect', real_bag(HUSKY), '--topic', HUSKY_ODOM, '--out', tmp_path, '--label', 'bumpy',
             '--window', '10s', '--stride', '50')
    files = os.listdir(tmp_path / 'bumpy')
    assert '%d feature vectors' % len(files) in out
    # 3952 messages at 10 Hz: the first vector needs 10 s of rows, then one every 50 messages
    assert 70 <= len(files) <= 80
    assert json.loads((tmp_path / 'bumpy' / files[0]).read_text())['config']['window'] == '10s'


def test_learn_with_only_nominal_vectors(trained):
    learn = trained['learn']
    assert os.path.isfile(trained['model'])
    assert learn['trained'] is True and learn['report'] is None
    assert learn['config'] == {'feature_set': 'motion', 'window': WINDOW, 'topic_type': 'nav_msgs/Odometry'}
    model = json.loads(trained['model'].read_text())
    assert model['format'] == 'cc_log-model' and model['threshold'] == learn['threshold']
    assert learn['info']['vectors_nominal'] == trained['collect']['vectors']
    assert learn['info']['vectors_anomalous'] == 0


def test_learn_with_a_test_directory_reports_the_table(trained, real_bag, tmp_path):
    ok('collect', real_bag(JERKY), '--topic', '/odom', '--out', tmp_path / 'test', '--label', 'jerky',
       '--window', WINDOW, '--stride', '1')
    jerky = len(os.listdir(tmp_path / 'test' / 'jerky'))
    result = ok_json('learn', '--train', trained['train'], '--test', tmp_path / 'test', '--model',
                     tmp_path / 'model.json')
    report = result['report']
    assert report['total'] == jerky == report['tp'] + report['fn']
    assert report['tp'] > jerky // 2  # jerky driving looks anomalous to a model of normal driving
    text = ok('learn', '--test', tmp_path / 'test', '--model', trained['model'])  # evaluate only
    assert 'Total            %d' % jerky in text and 'Recall' in text and 'Saved' not in text


# -- replay ---------------------------------------------------------------------------------------------------

def test_replay_json_fields_match_the_bag_and_the_files(replayed):
    from cc_log.storage import log_format
    from cc_log.base import msg_codec
    summary, bag = replayed['summary'], replayed['bag']
    assert list(summary) == ['input_messages', 'raw_json_bytes', 'stored_bytes', 'windows', 'drift', 'online',
                             'keep_budget', 'absent_route_topics', 'messages_restamped', 'restamped_by_topic',
                             'messages_trimmed_silent']
    assert summary['absent_route_topics'] == []  # no route
    assert summary['messages_restamped'] == 0 and summary['restamped_by_topic'] == {}  # every stamp on the clock
    assert summary['online'] == []  # no classifier learns online here
    assert summary['keep_budget']['windows_skipped'] == 0  # no keep budget: every window kept
    records = bag_messages(bag, ['/odom', '/scan'])
    assert summary['input_messages'] == len(records) == 542
    # estimated from a sample of the messages (replay does not decode them all)
    assert summary['raw_json_bytes'] == pytest.approx(sum(msg_codec.row_json_bytes(msg) for _, _, msg in records),
                                                      rel=0.01)
    windows = summary['windows']
    assert windows, 'jerky driving should open at least one window'
    files = log_format.window_files(str(replayed['out']))
    assert sorted(window['path'] for window in windows) == files
    assert summary['stored_bytes'] == sum(os.path.getsize(path) for path in files)
    for window in windows:
        assert list(window) == ['name', 'start', 'end', 'messages', 'files', 'path']
        assert window['files'] == [window['path']] and window['name'] == log_format.window_key(window['path'])[
            len(str(replayed['out'])) + 1:]
        metadata, saved = log_format.read_window(window['path'])
        assert window['messages'] == len(saved)
        assert window['start'] == saved[0].stamp == min(record.stamp for record in saved)
        assert window['end'] == saved[-1].stamp == max(record.stamp for record in saved)
        assert {record.topic for record in saved} == {'/odom', '/scan'}
        header = [r.msg.header.stamp.to_sec() for r in saved if r.topic == '/odom']
        assert window['start'] <= min(header) and max(header) <= window['end']
    assert [w['start'] for w in windows] == sorted(w['start'] for w in windows)


def test_replay_nominal_run_and_bag_lz4_format(trained, real_bag, tmp_path):
    bag = real_bag(JERKY)
    summary = ok_json('replay', bag, '--topic', '/odom', '--model', trained['model'], '--out', tmp_path,
                      '--format', 'bag-lz4', '--pre', '1s', '--post', '1s')
    assert summary['input_messages'] == 271  # only the driving topic without --side-topic
    assert summary['windows']
    for window in summary['windows']:
        assert window['path'].endswith('.bag')
        with open(window['path'], 'rb') as stream:
            assert stream.read(13) == b'#ROSBAG V2.0\n'
    info = ok_json('info', tmp_path)
    assert [w['codec'] for w in info['windows']] == ['bag-lz4'] * len(summary['windows'])
    assert [w['messages'] for w in info['windows']] == [w['messages'] for w in summary['windows']]
    lines = ok('cat', summary['windows'][0]['path']).splitlines()
    assert len(lines) == summary['windows'][0]['messages'] and json.loads(lines[0])['topic'] == '/odom'
    text = ok('replay', bag, '--topic', '/odom', '--model', trained['model'], '--out', tmp_path / 'text')
    assert '271 messages in' in text and 'window(s)' in text


def test_replay_says_how_many_messages_it_placed_at_the_clock(trained, real_bag, tmp_path):
    """A laser scanner whose every 10th header stamp is 100 s ahead of the bag's clock: those scans are placed at
    their arrival, and the summary says how many, per topic (they were counted only on the live node's
    /diagnostics)."""
    import rosbag
    bag = str(tmp_path / 'ahead.bag')
    scans = 0
    with rosbag.Bag(real_bag(JERKY)) as source, rosbag.Bag(bag, 'w') as out:
        for topic, msg, t in source.read_messages(topics=['/odom', '/scan']):
            if topic == '/scan':
                scans += 1
                if scans % 10 == 0:
                    msg.header.stamp.secs += 100
            out.write(topic, msg, t)
    args = ('replay', bag, '--topic', '/odom', '--side-topic', '/scan', '--model', trained['model'])
    summary = ok_json(*args + ('--out', tmp_path / 'json'))
    assert summary['restamped_by_topic'] == {'/scan': scans // 10} and summary['messages_restamped'] == scans // 10
    text = ok(*args + ('--out', tmp_path / 'text'))
    assert '  %d messages placed at the clock, their header stamps off it (/scan: %d)\n' % (scans // 10, scans // 10) \
        in text


# -- info, cat, export ----------------------------------------------------------------------------------------

def test_info_of_a_directory_and_of_a_file(replayed):
    summary = replayed['summary']
    info = ok_json('info', replayed['out'])
    assert len(info['windows']) == len(summary['windows'])
    assert info['total']['messages'] == sum(w['messages'] for w in summary['windows'])
    assert info['total']['bytes'] == summary['stored_bytes']
    first = info['windows'][0]
    assert first['codec'] == 'bag-lz4'
    assert first['start'] == summary['windows'][0]['start'] and first['end'] == summary['windows'][0]['end']
    assert set(first['topics']) == {'/odom', '/scan'} and sum(first['topics'].values()) == first['messages']
    assert first['reason'] == 'classifier' and first['triggers']
    assert first['min_score'] < first['threshold']  # a classifier trigger means score below the threshold
    text = ok('info', summary['windows'][0]['path'])
    assert 'codec      bag-lz4' in text and 'trigger    classifier' in text


def test_cat_decodes_every_message_and_other_cc_log_files(replayed, trained):
    window = replayed['summary']['windows'][0]
    lines = ok('cat', window['path']).splitlines()
    assert len(lines) == window['messages']
    rows = [json.loads(line) for line in lines]
    assert rows[0]['stamp'] == window['start'] and rows[-1]['stamp'] == window['end']
    odom = [row for row in rows if row['topic'] == '/odom']
    assert odom[0]['type'] == 'nav_msgs/Odometry' and 'twist' in odom[0]['msg']
    only = ok('cat', window['path'], '--topic', '/scan', '--metadata').splitlines()
    assert json.loads(only[0])['metadata']['codec'] == 'bag-lz4'
    assert len(only) - 1 == sum(1 for row in rows if row['topic'] == '/scan')
    model = ok('cat', trained['model']).splitlines()
    assert len(model) == 1 and json.loads(model[0])['format'] == 'cc_log-model'
    folder = trained['train'] / 'nominal'
    vector = json.loads(ok('cat', folder / sorted(os.listdir(folder))[0]))
    assert len(vector['features']) == len(json.loads(model[0])['scaler']['mean'])


def test_cat_refuses_files_that_are_not_cc_log(real_bag, tmp_path):
    assert 'not a cc_log window' in fails('cat', real_bag(HUSKY))  # a plain rosbag is no window file
    other = tmp_path / 'other.json'
    other.write_text('{"a": 1}')
    assert 'not a cc_log file' in fails('cat', other)


def test_export_to_bag_csv_and_jsonl(replayed, tmp_path):
    import rosbag
    out, summary = replayed['out'], replayed['summary']
    total = sum(w['messages'] for w in summary['windows'])
    result = ok_json('export', out, '--to', 'bag', '--out', tmp_path / 'all.bag')
    assert result['messages'] == total
    with rosbag.Bag(str(tmp_path / 'all.bag')) as bag:
        assert bag.get_message_count() == total
        assert set(bag.get_type_and_topic_info().topics) == {'/odom', '/scan'}
        first = next(bag.read_messages(topics=['/odom']))
        assert first.message._type == 'nav_msgs/Odometry'
    result = ok_json('export', out, '--to', 'csv', '--out', tmp_path / 'csv')
    odom_csv = tmp_path / 'csv' / 'odom.csv'
    assert str(odom_csv) in result['files']
    odom_lines = odom_csv.read_text().splitlines()
    assert odom_lines[0].startswith('stamp,header.seq,header.stamp,')
    assert len(odom_lines) - 1 == sum(1 for line in ok('cat', out, '--topic', '/odom').splitlines())
    ok('export', out, '--to', 'jsonl', '--out', tmp_path / 'odom.jsonl', '--topic', '/odom')
    assert (tmp_path / 'odom.jsonl').read_text().splitlines() == ok('cat', out, '--topic', '/odom').splitlines()


# -- codecs, plot, simulate -----------------------------------------------------------------------------------

TABLE_2 = ['none', 'LZ4', 'LZFSE', 'ZIP', 'gzip', 'bzip2', 'LZMA-6', 'zstd', 'cc_log bag-lz4', 'cc_log json-xz']


def test_codecs_on_a_bag_topic(real_bag):
    from cc_log.base import msg_codec
    bag = real_bag(HUSKY)
    table = ok_json('codecs', bag, '--topic', HUSKY_ODOM)
    raw = sum(msg_codec.row_json_bytes(msg) for _, _, msg in bag_messages(bag, [HUSKY_ODOM]))
    assert table['messages'] == 3952 and table['raw_json_bytes'] == raw
    rows = {row['codec']: row for row in table['rows']}
    assert [row['codec'] for row in table['rows']] == TABLE_2
    assert rows['none']['size'] == raw and rows['none']['ratio'] == 100.0
    for name in TABLE_2[1:]:
        row = rows[name]
        if name in ('LZ4', 'LZFSE', 'zstd') and not row['available']:  # optional Python bindings: said so
            assert row['size'] is None and 'no Python binding' in row['note']
            continue
        assert 0 < row['size'] < raw and row['mb_s'] > 0
        assert abs(row['ratio'] - 100.0 * row['size'] / raw) < 1e-9
    assert rows['LZMA-6']['size'] < rows['gzip']['size']


def test_codecs_on_window_files(replayed):
    table = ok_json('codecs', replayed['out'])
    assert table['source']['topics'] == ['/odom', '/scan']
    assert table['messages'] == sum(w['messages'] for w in replayed['summary']['windows'])
    text = ok('codecs', replayed['summary']['windows'][0]['path'], '--topic', '/odom')
    for name in TABLE_2:
        assert '\n%s ' % name in text


def test_plot_writes_a_png(replayed, trained, tmp_path):
    png = tmp_path / 'run.png'
    result = ok_json('plot', replayed['out'], '--bag', replayed['bag'], '--model', trained['model'],
                     '--out', png)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 10000
    assert result['windows'] == len(replayed['summary']['windows'])
    assert result['speed_samples'] == 271 and result['scores'] > 0 and result['triggers'] > 0
    only = ok_json('plot', replayed['summary']['windows'][0]['path'], '--out', tmp_path / 'w.png')
    window_odom = ok('cat', replayed['summary']['windows'][0]['path'], '--topic', '/odom')
    assert only['speed_samples'] == len(window_odom.splitlines())


def test_simulate_writes_bag_and_truth(tmp_path):
    import rosbag
    bag = tmp_path / 'out.bag'
    result = ok_json('simulate', '--minutes', '1', '--anomalies', '1', '--seed', '1', '--rate', '20', bag)
    truth = json.loads((tmp_path / 'out.bag.truth.json').read_text())
    assert result['truth'] == str(bag) + '.truth.json'
    assert len(truth['anomalies']) == result['anomalies'] == 1
    with rosbag.Bag(str(bag)) as reader:
        assert reader.get_type_and_topic_info().topics['/odom'].msg_type == 'nav_msgs/Odometry'
        assert 1150 <= reader.get_message_count(['/odom']) <= 1250  # 60 s at 20 Hz
    again = run('simulate', '--minutes', '1', '--anomalies', '1', '--seed', '1', '--rate', '20',
                tmp_path / 'again.bag', '--json', '--progress')
    assert again.returncode == 0 and '\rsimulate [' in again.stderr and '100%' in again.stderr
    assert json.loads(again.stdout)['truth_anomalies'] == result['truth_anomalies']  # same seed, same run
    assert 'exists' in fails('simulate', '--minutes', '1', '--anomalies', '0', bag)


def test_simulate_writes_a_camera_and_a_scan_at_their_rates(tmp_path):
    import rosbag
    from cc_log.sim import sensors
    bag = tmp_path / 'cameras.bag'
    result = ok_json('simulate', '--minutes', '0.1', '--anomalies', '0', '--camera', '--scan', bag)
    assert result['camera'] is True and result['scan'] is True
    with rosbag.Bag(str(bag)) as reader:
        topics = reader.get_type_and_topic_info().topics
        seconds = reader.get_end_time() - reader.get_start_time()
        image = next(msg for _, msg, _ in reader.read_messages([sensors.CAMERA_TOPIC]))
    assert topics[sensors.CAMERA_TOPIC].msg_type == 'sensor_msgs/Image'
    assert topics[sensors.SCAN_TOPIC].msg_type == 'sensor_msgs/LaserScan'
    assert abs(seconds - 6.0) < 0.1
    for topic, rate in ((sensors.CAMERA_TOPIC, sensors.CAMERA_RATE), (sensors.SCAN_TOPIC, sensors.SCAN_RATE)):
        assert abs(topics[topic].message_count - rate * 6.0) <= 1, (topic, topics[topic].message_count)
        assert abs(topics[topic].frequency - rate) < 0.05 * rate, (topic, topics[topic].frequency)
    assert (image.width, image.height, image.encoding) == (sensors.WIDTH, sensors.HEIGHT, 'rgb8')


# -- progress -------------------------------------------------------------------------------------------------

def test_progress_only_on_stderr_and_only_when_asked(replayed, trained):
    args = ('replay', replayed['bag'], '--topic', '/odom', '--model', trained['model'], '--json')
    quiet = run(*(args + ('--out', replayed['out'].parent / 'quiet')))
    assert quiet.returncode == 0 and quiet.stderr == ''  # stderr is not a terminal here
    loud = run(*(args + ('--out', replayed['out'].parent / 'loud', '--progress')))
    assert loud.returncode == 0
    assert loud.stderr.startswith('\rreplay ') and loud.stderr.endswith('\n')
    assert json.loads(loud.stdout)['input_messages'] == 271 and '\r' not in loud.stdout
    info = run('info', replayed['out'], '--progress', '--json')
    assert '\rinfo [' in info.stderr and '100%' in info.stderr and json.loads(info.stdout)['windows']


def test_progress_bar_counts_sets_totals_relabels_and_spins():
    from cc_log.offline.progress import Progress, SPINNER
    stream = io.StringIO()
    with Progress('read', 4, enabled=True, stream=stream) as bar:
        for _ in range(4):
            bar.update()
    assert stream.getvalue().startswith('\rread [') and stream.getvalue().endswith('] 100%  4/4  00:00\n')
    stream = io.StringIO()
    with Progress('replay', enabled=True, stream=stream) as bar:
        bar.set(5)
        bar.label = 'replay (1/2 bags)'
        bar.set(10, 10)
    assert '\rreplay  ' in stream.getvalue() and '\rreplay (1/2 bags) [' in stream.getvalue()
    assert stream.getvalue().endswith(' 100%  10/10  00:00\n')
    stream = io.StringIO()
    with Progress('learn', enabled=True, stream=stream, interval=0.01).busy():
        deadline = time.time() + 30
        while not any('learn %s ' % c in stream.getvalue() for c in SPINNER) and time.time() < deadline:
            time.sleep(0.01)
    assert any('learn %s ' % c in stream.getvalue() for c in SPINNER) and stream.getvalue().endswith('\n')
    quiet = io.StringIO()
    with Progress('read', 3, enabled=False, stream=quiet).busy() as bar:
        bar.update()
        bar.set(2, 3)
    assert quiet.getvalue() == ''


# -- bad input: one line, non-zero exit -------------------------------------------------------------------------

@pytest.fixture
def truncated_bag(real_bag, tmp_path):
    """The first 4 kB of a real bag."""
    path = tmp_path / 'truncated.bag'
    with open(real_bag(HUSKY), 'rb') as stream:
        path.write_bytes(stream.read(4096))
    return path


@pytest.fixture
def unindexed_bag(real_bag, tmp_path):
    """A bag as a recorder killed mid-run leaves it: chunks on disk, no index (copied before close)."""
    import rosbag
    path = tmp_path / 'recording.bag'
    copy = tmp_path / 'unindexed.bag'
    with rosbag.Bag(real_bag(JERKY)) as source:
        writer = rosbag.Bag(str(path), 'w', chunk_threshold=4096)
        for number, (topic, msg, stamp) in enumerate(source.read_messages()):
            writer.write(topic, msg, stamp)
            if number > 300:
                break
        writer._file.flush()
        shutil.copy(str(path), str(copy))
        writer.close()
    with pytest.raises(rosbag.ROSBagUnindexedException):
        rosbag.Bag(str(copy))
    return copy


def _bag_commands(bag, model, tmp_path, topic='/odom'):
    """Every command that reads a bag, on ``bag``."""
    return [
        ('replay', bag, '--topic', topic, '--model', model, '--out', tmp_path / 'logs'),
        ('collect', bag, '--topic', topic, '--out', tmp_path / 'vectors'),
        ('codecs', bag, '--topic', topic),
    ]


def test_missing_files(trained, replayed, tmp_path):
    missing = tmp_path / 'nope.bag'
    for args in _bag_commands(missing, trained['model'], tmp_path):
        line = fails(*args)
        assert str(missing) in line and 'no such' in line
    assert 'no such' in fails('replay', replayed['bag'], '--topic', '/odom', '--model', tmp_path / 'm.json',
                              '--out', tmp_path / 'x')
    for command in ('info', 'cat'):
        assert 'no such file or directory' in fails(command, missing)
    assert 'no such' in fails('export', missing, '--to', 'jsonl', '--out', tmp_path / 'x.jsonl')
    assert 'no such' in fails('plot', replayed['out'], '--bag', missing, '--out', tmp_path / 'x.png')
    assert 'no such directory' in fails('learn', '--train', tmp_path / 'none', '--model', tmp_path / 'm.json')
    assert 'no cc_log window files' in fails('info', tmp_path)
    assert not os.path.exists(tmp_path / 'logs') and not os.path.exists(tmp_path / 'vectors')


def test_truncated_bag(truncated_bag, trained, tmp_path):
    for args in _bag_commands(truncated_bag, trained['model'], tmp_path):
        line = fails(*args)
        assert str(truncated_bag) in line and 'truncated' in line


def test_unindexed_bag(unindexed_bag, trained, tmp_path):
    for args in _bag_commands(unindexed_bag, trained['model'], tmp_path):
        line = fails(*args)
        assert str(unindexed_bag) in line and 'unindexed' in line


def test_topic_not_in_bag(real_bag, trained, tmp_path):
    bag = real_bag(HUSKY)
    for args in _bag_commands(bag, trained['model'], tmp_path, topic='/odom'):
        line = fails(*args)
        assert 'topic /odom is not in the bag' in line and HUSKY_ODOM in line  # the real topics are listed
    assert 'needs --topic' in fails('codecs', bag)


def test_wrong_message_type(real_bag, trained, tmp_path):
    bag = real_bag(ALFA)
    topic = '/failure_status/engines'
    for command in ('replay', 'collect'):
        args = [args for args in _bag_commands(bag, trained['model'], tmp_path, topic) if args[0] == command][0]
        line = fails(*args)
        assert 'std_msgs/Bool' in line and 'expected nav_msgs/Odometry' in line


def test_wrong_message_type_for_plot(replayed, real_bag, tmp_path):
    line = fails('plot', replayed['out'], '--bag', real_bag(HUSKY), '--topic', '/imu/data', '--out',
                 tmp_path / 'x.png')
    assert 'topic /imu/data is sensor_msgs/Imu, expected nav_msgs/Odometry' in line
    assert not os.path.exists(tmp_path / 'x.png')


def test_model_from_another_feature_configuration(trained, replayed, real_bag, tmp_path):
    # vectors of another feature window than the model's
    ok('collect', real_bag(JERKY), '--topic', '/odom', '--out', tmp_path / 'other', '--label', 'jerky',
       '--window', '10', '--stride', '1')
    line = fails('learn', '--test', tmp_path / 'other', '--model', trained['model'])
    assert 'other features' in line and "window '10'" in line
    line = fails('learn', '--train', trained['train'], '--test', tmp_path / 'other', '--model', tmp_path / 'm.json')
    assert 'window' in line and str(tmp_path / 'other') in line
    # a model file claiming a feature configuration its arrays do not fit
    document = json.loads(trained['model'].read_text())
    document['config']['feature_set'] = 'raw'
    other = tmp_path / 'raw-model.json'
    other.write_text(json.dumps(document))
    line = fails('replay', replayed['bag'], '--topic', '/odom', '--model', other, '--out', tmp_path / 'logs')
    assert str(other) in line and 'need' in line
    assert 'not a cc_log model' in fails('replay', replayed['bag'], '--topic', '/odom', '--model',
                                         replayed['bag'], '--out', tmp_path / 'logs')


def test_bad_window_files_and_option_values(replayed, trained, tmp_path):
    window = replayed['summary']['windows'][0]['path']
    cut = tmp_path / os.path.basename(window)
    with open(window, 'rb') as stream:
        cut.write_bytes(stream.read(200))
    for command in ('info', 'cat'):
        line = fails(command, cut)
        assert str(cut) in line and 'truncated' in line
    line = fails('replay', replayed['bag'], '--topic', '/odom', '--model', trained['model'], '--out', tmp_path,
                 '--pre', 'lots', status=2)
    assert "pre: 'lots' is not a message count" in line
    assert 'window' in fails('collect', replayed['bag'], '--topic', '/odom', '--out', tmp_path, '--window',
                             '-5', status=2)
    assert 'invalid choice' in fails('export', replayed['out'], '--to', 'xml', '--out', tmp_path, status=2)


def test_recover_renames_a_complete_leftover_and_reports(tmp_path, real_bag):
    from cc_log.storage import log_format
    from cc_log.base.records import LogWindow, Record, Trigger
    import rosbag
    with rosbag.Bag(real_bag('husky_outdoor_2015.bag')) as bag:
        records = [Record(m.header.stamp.to_sec(), topic, m) for topic, m, _ in
                   bag.read_messages(topics=['/husky_velocity_controller/odom'])][:50]
    final, _ = log_format.write_window(LogWindow(records, [Trigger(records[0].stamp, 'test', -1.0)]),
                                       str(tmp_path), 'json-xz')
    leftover = final + '.tmp-999999999'  # as if its writer had been killed before the rename
    os.rename(final, leftover)
    result = ok_json('recover', tmp_path)
    [outcome] = result['leftovers']
    assert outcome['status'] == 'complete' and outcome['messages'] == 50
    assert not os.path.exists(leftover)
    _, back = log_format.read_window(outcome['path'])
    assert [r.stamp for r in back] == [r.stamp for r in records]
    assert ok_json('recover', tmp_path)['leftovers'] == []


def _odom_window(real_bag, count=50):
    """A window of ``count`` odometry messages of a real bag, triggered at its first."""
    import rosbag
    from cc_log.base.records import LogWindow, Record, Trigger
    with rosbag.Bag(real_bag('husky_outdoor_2015.bag')) as bag:
        records = [Record(m.header.stamp.to_sec(), topic, m) for topic, m, _ in
                   bag.read_messages(topics=['/husky_velocity_controller/odom'])][:count]
    return LogWindow(records, [Trigger(records[0].stamp, 'test', -1.0)])


def _leftover(directory, name, real_bag, fmt='json-xz'):
    """A complete window file left as ``directory/name`` (a ``*.tmp-<pid>`` of a writer gone)."""
    from cc_log.storage import log_format
    final, _ = log_format.write_window(_odom_window(real_bag), str(directory), fmt)
    leftover = os.path.join(str(directory), name)
    os.rename(final, leftover)
    return leftover


def test_recover_of_a_logging_directory_recovers_its_context_track_too(tmp_path, real_bag):
    """Issue 42 item 18: ``cclog recover LOGDIR`` said "no leftovers" while LOGDIR/context/ held one."""
    from test_reliability import DEAD_PID
    context = tmp_path / 'context'
    context.mkdir()
    leftover = _leftover(context, 'cc_log_context_20150521T191138.027Z.bag.tmp-%d' % DEAD_PID, real_bag, 'bag-lz4')
    result = run('recover', tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert 'no leftovers' not in result.stdout and leftover in result.stdout, result.stdout
    assert not os.path.exists(leftover) and os.path.exists(str(context / 'cc_log_context_20150521T191138.027Z.bag'))
    assert ok('recover', tmp_path).strip() == 'no leftovers'


def test_recover_prints_a_leftover_name_with_its_terminal_escapes_shown(tmp_path, real_bag):
    """Issue 42 item 20: a leftover's name reaches the terminal through safe_input.printable, never raw."""
    from test_reliability import DEAD_PID
    hostile = '\x1b]0;owned\x07\x1b[2J\u202e'
    _leftover(tmp_path, 'cc_log_20150521T191138.027Z_%s.json.xz.tmp-%d' % (hostile, DEAD_PID), real_bag)
    text = ok('recover', tmp_path)
    assert '\x1b' not in text and '\x07' not in text and '\u202e' not in text, repr(text)
    assert 'complete' in text and 'cc_log_20150521T191138.027Z_\\x1b]0;owned\\x07\\x1b[2J\\u202e.json.xz' in text


# -- a full disk: offline commands retry briefly, then fail naming what was not written ------------------------

def test_replay_into_a_full_disk_retries_then_fails_naming_the_directory_and_the_loss(trained, replayed,
                                                                                      small_tmpfs):
    from conftest import fill_disk
    from cc_log.storage import window_writer
    disk = small_tmpfs('1m')
    out = os.path.join(disk, 'logs')
    os.makedirs(out)
    fill_disk(os.path.join(disk, 'filler'))
    started = time.monotonic()
    line = fails('replay', replayed['bag'], '--topic', '/odom', '--side-topic', '/scan', '--model',
                 trained['model'], '--out', out, '--pre', '10', '--post', '10')
    assert time.monotonic() - started >= window_writer.OFFLINE_RETRY_SECONDS  # it retried first
    assert line.startswith('cclog replay: error: %s: ' % out), line
    assert 'messages) not written' in line and 'No space left on device' in line, line
    assert 'retrying every' not in line  # nothing is left retrying once the command has exited
    assert [name for name in os.listdir(out) if '.tmp-' in name] == []


def test_collect_into_a_full_disk_retries_then_fails_naming_the_directory(trained, real_bag, small_tmpfs):
    from conftest import fill_disk
    disk = small_tmpfs('1m')
    fill_disk(os.path.join(disk, 'filler'))
    out = os.path.join(disk, 'vectors')
    line = fails('collect', real_bag(NORMAL), '--topic', '/odom', '--out', out, '--window', WINDOW, '--stride', 5)
    from cc_log.storage.bag import bagio
    from cc_log.features import FeatureConfig
    expected = len(bagio.feature_vectors(real_bag(NORMAL), '/odom', FeatureConfig('motion', WINDOW), 5)[0])
    assert line.startswith('cclog collect: error: %s: ' % os.path.join(out, 'nominal')), line
    assert '%d of %d feature vectors not written' % (expected, expected) in line, line
    assert 'No space left on device' in line, line
    assert [name for name in os.listdir(os.path.join(out, 'nominal')) if '.tmp-' in name] == []


# -- trigger (a live smart logger's ~trigger_window; the call itself: manual_trigger.test) ----------------------

def test_trigger_without_a_master_is_one_line():
    result = run('trigger', '--reason', 'bump')
    assert result.returncode == 1 and result.stdout == ''
    assert result.stderr == ('cclog trigger: error: no ROS master at http://127.0.0.1:1 (start roscore, or set '
                             "ROS_MASTER_URI to the robot's)\n")


def test_trigger_finds_the_one_smart_logger_or_says_what_runs():
    from cc_log.base.errors import CommandError
    from cc_log.offline.cli.trigger_cmd import trigger_service
    services = ['/rosout/get_loggers', '/robot1/smart_logger/trigger', '/robot1/smart_logger/trigger_window']
    assert trigger_service(services, ['/rosout']) == '/robot1/smart_logger/trigger_window'
    assert trigger_service(services, [], 'robot1/smart_logger/') == '/robot1/smart_logger/trigger_window'
    with pytest.raises(CommandError, match=r'^--node /smart_logger: no trigger_window service there \(smart '
                                           r'loggers running: /robot1/smart_logger\)$'):
        trigger_service(services, [], '/smart_logger')
    with pytest.raises(CommandError, match=r'^several smart loggers are running \(/a, /robot1/smart_logger\): '
                                           r'choose one with --node$'):
        trigger_service(services + ['/a/trigger_window'], [])
    with pytest.raises(CommandError, match=r'^no smart logger is running \(no trigger_window service; nodes '
                                           r'running: /collect_logger, /rosout\)$'):
        trigger_service(['/rosout/get_loggers'], ['/rosout', '/collect_logger'])


def test_trigger_durations_are_checked_where_they_enter():
    result = run('trigger', '--before', 'soon')
    assert result.returncode == 2 and result.stderr.count('\n') == 1 and "'soon' is not a duration" in result.stderr

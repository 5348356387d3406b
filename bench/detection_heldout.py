#!/usr/bin/env python3
"""Detection on held-out public robots, as a user runs it: cclog collect / learn on the first 20 minutes of a
robot's driving, cclog replay of the rest with and without the simulator's anomalies injected; drift at a place
change, with and without online learning.

    /usr/bin/python3 bench/heldout_data.py                       # the bags (once; bench/HELDOUT_SOURCES.md)
    nice -n 10 /usr/bin/python3 bench/detection_heldout.py       # every robot, both settings, seeds 0 1 2
    /usr/bin/python3 bench/detection_heldout.py --robots tuc --settings 2s --seeds 0 --no-drift   # quick
    /usr/bin/python3 bench/detection_heldout.py --injection robot --seeds 0 --no-drift --explain  # what was flagged

Robots (bench/heldout_data.py): ``tuc`` (indoor robot, 10 Hz: corridor 37.8 min, then a lecture hall 23.1 min),
``smartloc`` (a car in city traffic, 5 Hz: Berlin 24.6 min, then Frankfurt 31 min), ``mrclam`` (iRobot Create,
~66 Hz: robot 1's 24.8 min, then robots 2.. of the same kind, ``--mrclam-robots``).

Per robot: its runs in order; the first ``--train-minutes`` (20) of driving, summed over runs, are cut into bags
and go through ``cclog collect`` (one directory per piece, the default stride) and ``cclog learn`` (its defaults:
trim 1 %); the rest of every run is replayed by ``cclog replay --json`` (classify every 50 ms, retrigger event):

- without injection: every window is false (false windows per hour, per replayed run);
- with ``sim.inject_anomalies`` (all six types, one each, per seed, into each replayed run; ``--injection``:
  ``robot`` = at the run's robot's own scale, ``sim.nominal_envelope`` of the training driving, or ``bwibot`` =
  the simulator's magnitudes): caught = a classifier trigger (read from the window files) in [onset, end +
  feature window]; latency = first such trigger - onset (target <= 0.5 s); span kept = the share of [onset,
  end] inside saved windows (target >= 95 %); false windows = windows with no trigger near an event; kept /
  ideal = odometry messages in saved windows / those within [onset - 2 s, end + 2 s] of an event (target <=
  1.5x); event length = end - onset: the anomaly and the return to the recorded twist (after it the recording
  carries on from where the anomaly left the base).

Settings (``--settings``): ``defaults`` = exactly the CLI's (feature window 2 s, pre/post 2 s);
``2s`` = docs/DETECTION.md's recommendation for ~10 Hz robots (window 2 s, pre/post 2 s, the ideal's margin);
``dynamics`` = the defaults with the level-free ``dynamics`` feature set (how the motion changes, never how fast:
the remedy for a new speed regime that the drift report names).

``--tune N``: the learnt model is tuned by ``cclog tune --max-false-per-hour N`` on the training bags (the nominal
driving a user has when the model is new; anomalies injected at the first ``--injection`` scale) and every replay
uses the tuned model; the report says what tune estimated (recall at the model's threshold and at the chosen one,
what it lost).

Drift (``--no-drift`` skips): the robot's rest, the same place first and then the new place (``DRIFT_FROM``:
the lecture hall, Frankfurt), replayed as one bag by ``cclog replay`` (its drift monitor: is drift reported
within 2 min of the switch?) and again with ``learn_online: true`` (a ``--config`` whose classifier learns
online, the defaults learn_every 2000, guard 10 s): false windows per hour in each 5 min after the switch and
from 10 min after it on (target <= 2/h); then, per seed, the six anomalies injected into the new place from 10 min
after the switch on (at the scale of the training driving and of the new place's first 10 min), replayed the same
two ways: what is still caught once online learning has adapted (it learns the new place's own flags). ``cclog
replay`` refits in its own thread: a refit lands at the message it was due, as on a robot.
"""
import argparse
import collections
import contextlib
import io
import json
import os
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
from common import count_of  # noqa: E402
import heldout_data  # noqa: E402

from cc_log import sim  # noqa: E402
from cc_log.features import DEFAULT_WINDOW  # noqa: E402
from cc_log.offline import cli  # noqa: E402
from cc_log.storage import log_format  # noqa: E402
from cc_log.storage.bag import bagio  # noqa: E402

TOPIC = heldout_data.TOPIC
MARGIN = 2.0            # s each side of an event: issue 31's ideal
LATENCY = 0.5
MIN_SPAN_KEPT = 0.95
SETTINGS = collections.OrderedDict([
    ('defaults', {}),                                                   # the CLI's own defaults
    ('2s', {'window': '2s', 'pre': '2s', 'post': '2s'}),              # docs/DETECTION.md, ~10 Hz robots
    ('dynamics', {'features': 'dynamics'}),                            # the defaults, the level-free feature set
])
DRIFT_FROM = {'tuc': 'tuc_lecture_hall', 'smartloc': 'smartloc_frankfurt_main_tower', 'mrclam': None}
BLOCK = 300.0           # s: false windows per block after the switch
ADAPTED = 600.0         # s after the switch: events injected from then on test the adapted model
EXPLAIN = 1.5           # s each side of a false window's trigger that --explain describes


def quiet_cli(argv):
    """``cclog ARGV`` in this process; (status, stdout text)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = cli.main(argv)
    if status:
        raise RuntimeError('cclog %s: exit %s\n%s' % (' '.join(argv), status, out.getvalue()))
    return out.getvalue()


def load_runs(robot, data, mrclam_robots):
    runs = [(os.path.basename(p)[:-4], list(bagio.read_messages(p, [TOPIC]))) for p in heldout_data.runs(robot, data)]
    if robot == 'mrclam':
        runs = runs[:mrclam_robots]
    return runs


def split(runs, seconds):
    """(training pieces, rest pieces): lists of (run name, records), the first ``seconds`` of driving summed over
    runs train, the rest of the run that crosses the cut and every later run are replayed."""
    train, rest, left = [], [], seconds
    for name, records in runs:
        duration = records[-1].stamp - records[0].stamp
        if left <= 0:
            rest.append((name, records))
        elif duration <= left:
            train.append((name, records))
            left -= duration
        else:
            cut = records[0].stamp + left
            train.append((name, [r for r in records if r.stamp < cut]))
            rest.append((name, [r for r in records if r.stamp >= cut]))
            left = 0
    return train, rest


def learn(train, setting, tmp, stride=None):
    """``cclog collect`` of every training piece (``--stride`` when given) and ``cclog learn`` of them all; (model
    path, the lines)."""
    dirs, lines = [], []
    for k, (name, records) in enumerate(train):
        bag = os.path.join(tmp, 'train%d.bag' % k)
        common.write_bag(bag, records)
        out = os.path.join(tmp, 'vectors%d' % k)
        argv = ['collect', bag, '--topic', TOPIC, '--out', out]
        for key in ('window', 'features'):
            if key in setting:
                argv += ['--' + key, setting[key]]
        if stride:
            argv += ['--stride', str(stride)]
        lines.append(quiet_cli(argv).strip())
        if os.path.isdir(os.path.join(out, 'nominal')):
            dirs.append(out)
    model = os.path.join(tmp, 'model.json')
    lines.append(quiet_cli(['learn', '--train'] + dirs + ['--model', model]).strip().splitlines()[0])
    return model, lines


def replay(records, model, setting, tmp, tag, config=None):
    """``cclog replay --json`` of ``records`` written as a bag; (windows with their trigger stamps, drift)."""
    bag = os.path.join(tmp, tag + '.bag')
    common.write_bag(bag, records)
    out = os.path.join(tmp, tag)
    argv = ['replay', bag, '--topic', TOPIC, '--model', model, '--out', out, '--json']
    for key in ('pre', 'post'):
        if key in setting:
            argv += ['--' + key, setting[key]]
    if config:
        argv += ['--config', config]
    result = json.loads(quiet_cli(argv))
    for window in result['windows']:
        meta, _ = log_format.read_window(window['path'])
        window['triggers'] = [t['stamp'] for t in meta.get('triggers', [])]
        window['why'] = [w.get('text', '') for w in (meta.get('triggers') or [{}])[0].get('why') or []]
    shutil.rmtree(out, ignore_errors=True)
    os.remove(bag)
    return result['windows'], result['drift']


def speed_steps(records):
    """(stamps, |dv/dt| between consecutive messages) of the reported forward speed: the steps the features see."""
    t = np.array([r.stamp for r in records])
    v = np.array([r.msg.twist.twist.linear.x for r in records])
    dt = np.diff(t)
    ok = dt > 1e-3
    return t[1:][ok], np.abs(np.diff(v)[ok] / dt[ok])


def what_was_flagged(records, windows, steps):
    """Per window of a nominal replay: (first trigger into the run s, speed range and largest speed step within
    EXPLAIN s of it); ``steps`` = speed_steps(records)."""
    t0, (at, step) = records[0].stamp, steps
    out = []
    for window in windows:
        trigger = (window['triggers'] or [window['start']])[0]
        near = [r.msg.twist.twist.linear.x for r in records if abs(r.stamp - trigger) <= EXPLAIN]
        close = step[np.abs(at - trigger) <= EXPLAIN]
        out.append((trigger - t0, min(near), max(near), float(close.max()) if len(close) else 0.0))
    return out


def drifted(monitors):
    """Whether a replay's drift monitor reported drift."""
    return int(bool(monitors and monitors[0].get('drift')))


def span_kept(entry, windows):
    """The share of [start, end] of an event inside saved windows."""
    length = entry['end'] - entry['start']
    covered = sum(max(0.0, min(w['end'], entry['end']) - max(w['start'], entry['start'])) for w in windows)
    return min(1.0, covered / length) if length > 0 else 1.0


def rate_of(records):
    """Messages per second on average (irregular sources: MRCLAM steps 10-40 ms)."""
    return (len(records) - 1) / (records[-1].stamp - records[0].stamp)


def reach_of(setting, rate):
    """The feature window in seconds (a trigger up to this long after an event's end still belongs to it)."""
    window = setting.get('window', DEFAULT_WINDOW)
    return float(window[:-1]) if window.endswith('s') else int(window) / rate


def tune(model, train, setting, tmp, budget, injection):
    """``cclog tune --json`` of ``model`` on the training bags ``learn`` wrote, anomalies injected at the scale
    ``injection``; (the tuned model's path, tune's record)."""
    tuned = os.path.join(tmp, 'tuned.json')
    argv = ['tune', '--model', model, '--topic', TOPIC, '--max-false-per-hour', '%g' % budget, '--out', tuned,
            '--json', '--injection-scale', injection]
    for k in range(len(train)):
        argv += ['--bag', os.path.join(tmp, 'train%d.bag' % k)]
    for key in ('pre', 'post'):
        if key in setting:
            argv += ['--' + key, setting[key]]
    return tuned, json.loads(quiet_cli(argv))


def evaluate(robot, runs, setting_name, seeds, injections, tmp, train_seconds, drift, stride=None, budget=None):
    setting = SETTINGS[setting_name]
    train, rest = split(runs, train_seconds)
    started = time.time()
    model, lines = learn(train, setting, tmp, stride)
    tuned = None
    if budget is not None:
        model, tuned = tune(model, train, setting, tmp, budget, injections[0])
    first = [r for _, records in train for r in records]
    envelope = sim.nominal_envelope(first, TOPIC)
    rate = rate_of(first)
    reach = reach_of(setting, rate)
    trained_steps = np.concatenate([speed_steps(records)[1] for _, records in train])
    out = {'robot': robot, 'setting': setting_name, 'lines': lines, 'rate': rate, 'reach': reach,
           'train_s': sum(r[-1].stamp - r[0].stamp for _, r in train), 'runs': [], 'events': [],
           'envelope': envelope, 'tune': tuned,
           'trained_steps': (float(np.quantile(trained_steps, 0.999)), float(trained_steps.max()))}
    for name, records in rest:
        hours = (records[-1].stamp - records[0].stamp) / 3600.0
        windows, monitors = replay(records, model, setting, tmp, 'nominal-' + name)
        row = {'run': name, 'hours': hours, 'false_nominal': len(windows), 'injected': {},
               'drift_nominal': drifted(monitors), 'flagged': what_was_flagged(records, windows, speed_steps(records))}
        for injection in injections:
            scale = dict(scale=envelope, limits=envelope) if injection == 'robot' else {}
            kept = need = false = drifts = 0
            for seed in seeds:
                try:
                    injected, truth = sim.inject_anomalies(records, sim.ANOMALY_TYPES, seed=seed, topic=TOPIC,
                                                           **scale)
                except ValueError as error:
                    row['injected'][injection] = 'not injected: %s' % error
                    break
                windows, monitors = replay(injected, model, setting, tmp, 'inj-%s-%s-%d' % (name, injection, seed))
                drifts += drifted(monitors)
                matches, f = common.match_anomalies(truth, windows, reach)
                false += f
                k, n = common.kept_messages(injected, TOPIC, windows, truth, MARGIN, MARGIN)
                kept, need = kept + k, need + n
                for m, entry in zip(matches, truth):
                    out['events'].append(dict(m, run=name, injection=injection, seed=seed,
                                              span=span_kept(entry, windows), length=entry['end'] - entry['start']))
            else:
                row['injected'][injection] = {'false': false, 'kept': kept, 'need': need, 'hours': hours * len(seeds),
                                              'drift': drifts, 'replays': len(seeds)}
        out['runs'].append(row)
    if drift and DRIFT_FROM.get(robot):
        out['drift'] = drift_test(robot, rest, model, setting, tmp, seeds, envelope, reach)
    out['seconds'] = time.time() - started
    return out


def drift_test(robot, rest, model, setting, tmp, seeds, envelope, reach):
    """The rest replayed as one bag, the place change at DRIFT_FROM: drift report and false windows after the
    switch, without and with online learning; then, per seed, the six anomalies injected into the new place from
    ADAPTED s after the switch on, at the scale of the training driving and at that of the new place's first
    ADAPTED s: what each still catches once online learning has adapted."""
    names = [name for name, _ in rest]
    switch_run = names.index(DRIFT_FROM[robot])
    records = [r for _, recs in rest for r in recs]
    switch = rest[switch_run][1][0].stamp
    end = records[-1].stamp
    config = os.path.join(tmp, 'online.yaml')
    with open(config, 'w') as stream:
        stream.write('triggers:\n  - {name: classifier, kind: classifier, learn_online: true}\n')
    result = {'switch_after_s': switch - records[0].stamp, 'after_s': end - switch}
    learned = [r for r in records if switch <= r.stamp < switch + ADAPTED]   # what online learning adapted to
    scales = [('the training', envelope), ('the new place', sim.nominal_envelope(learned, TOPIC))]
    for label, cfg in (('plain', None), ('online', config)):
        local = os.path.join(tmp, 'drift-' + label)
        os.makedirs(local, exist_ok=True)
        shutil.copy(model, os.path.join(local, 'model.json'))
        windows, monitors = replay(records, os.path.join(local, 'model.json'), setting, local, 'drift', cfg)
        starts = np.array([w['start'] for w in windows])
        blocks = []
        t = switch
        while t < end:
            blocks.append(int(((starts >= t) & (starts < min(t + BLOCK, end))).sum()))
            t += BLOCK
        late = (starts >= switch + 600.0).sum()
        late_hours = max(end - switch - 600.0, 0.0) / 3600.0
        before = (starts < switch).sum()
        kept_after = sum(max(0.0, w['end'] - max(w['start'], switch)) for w in windows) / (end - switch)
        monitor = monitors[0] if monitors else {}
        first = monitor.get('first_drift')
        result[label] = {
            'before': int(before), 'before_hours': (switch - records[0].stamp) / 3600.0, 'blocks': blocks,
            'late': int(late), 'late_rate': late / late_hours if late_hours else float('nan'),
            'drift': monitor.get('drift'), 'first_drift_after_switch': None if first is None else first - switch,
            'first_drift_into_replay': None if first is None else first - records[0].stamp,
            'peak': monitor.get('peak'), 'kept_after': kept_after, 'online': label == 'online' and os.path.exists(
                os.path.join(local, 'model.online.json')),
            'adapted': [(scale, injected_after(records, switch, model, setting, os.path.join(local, 'scale%d' % k),
                                               cfg, seeds, limits, reach))
                        for k, (scale, limits) in enumerate(scales)]}
    return result


def injected_after(records, switch, model, setting, tmp, config, seeds, envelope, reach):
    """Events caught among those injected into ``records`` from ADAPTED s after ``switch`` on at the scale of
    ``envelope`` (one replay per seed, the model copied afresh into ``tmp``, a new directory: no refit of another
    replay is resumed): {'events', 'caught', 'fast', 'spans', 'missed' (per type)} or {'error'}."""
    before = [r for r in records if r.stamp < switch + ADAPTED]
    after = [r for r in records if r.stamp >= switch + ADAPTED]
    out = {'events': 0, 'caught': 0, 'fast': 0, 'spans': 0, 'missed': collections.Counter()}
    os.makedirs(tmp)
    for seed in seeds:
        try:
            injected, truth = sim.inject_anomalies(after, sim.ANOMALY_TYPES, seed=seed, topic=TOPIC,
                                                   scale=envelope, limits=envelope)
        except ValueError as error:
            return {'error': str(error)}
        fresh = os.path.join(tmp, 'adapted-%d.json' % seed)
        shutil.copy(model, fresh)
        windows, _ = replay(before + injected, fresh, setting, tmp, 'adapted-%d' % seed, config)
        matches, _ = common.match_anomalies(truth, windows, reach)
        out['events'] += len(truth)
        out['caught'] += sum(m['caught'] for m in matches)
        out['fast'] += sum(m['caught'] and m['delay'] <= LATENCY for m in matches)
        out['spans'] += sum(span_kept(entry, windows) >= MIN_SPAN_KEPT for entry in truth)
        out['missed'].update(m['type'] for m in matches if not m['caught'])
    return out


def report(r, injections, explain=False):
    print('## %s, setting %s: %.1f Hz, trained on %.1f min, feature window %.2f s' % (
        r['robot'], r['setting'], r['rate'], r['train_s'] / 60.0, r['reach']))
    for line in r['lines']:
        print('  ' + line.replace('\n', '\n  '))
    print('  envelope of the training driving: %s' % ', '.join(
        '%s %.2f' % kv for kv in r['envelope']._asdict().items()))
    record = r['tune']
    if record:
        caught = record['caught_before']
        print('  cclog tune --max-false-per-hour %g on the training bags (anomalies at the %s scale; every replay '
              'below uses the tuned model): the model\'s threshold %.4g catches %d/%d injected (%s) with %d false '
              'window(s) in-sample; the chosen %.4g catches %d/%d%s with %d' % (
                  record['max_false_per_hour'], record['injection_scale'], record['threshold_before'], len(caught),
                  record['injected'], 'missed: ' + ', '.join(k for k in sim.ANOMALY_TYPES if k not in caught)
                  if len(caught) < record['injected'] else 'all', record['false_windows_before'],
                  record['threshold'], len(record['catches']), record['injected'],
                  ' (lost: %s)' % ', '.join(record['lost']) if record['lost'] else '', record['false_windows']))
    rows = []
    total_false = total_hours = 0.0
    for row in r['runs']:
        cells = [row['run'], '%.1f' % (row['hours'] * 60), row['false_nominal'],
                 '%.1f' % (row['false_nominal'] / row['hours']), 'yes' if row['drift_nominal'] else 'no']
        total_false += row['false_nominal']
        total_hours += row['hours']
        for injection in injections:
            inj = row['injected'].get(injection)
            if isinstance(inj, dict):
                cells += ['%.1f' % (inj['false'] / inj['hours']), '%.2fx' % (inj['kept'] / float(inj['need'])),
                          '%d/%d' % (inj['drift'], inj['replays'])]
            else:
                cells += [inj or '-', '-', '-']
        rows.append(cells)
    headers = ['replayed run', 'min', 'false windows', 'false/h', 'drift reported']
    for injection in injections:
        headers += ['false/h injected (%s)' % injection, 'kept/ideal (%s)' % injection,
                    'drift reported (%s)' % injection]
    common.table(headers, rows)
    print('all replayed: %d false windows in %.2f h = %.1f/h (target <= 1/h)' % (
        total_false, total_hours, total_false / total_hours if total_hours else 0.0))
    if explain:
        print('what the false windows flagged (speed within %g s of the trigger; training speed steps |dv/dt|: '
              '99.9th percentile %.2f, largest %.2f m/s^2):' % ((EXPLAIN,) + r['trained_steps']))
        for row in r['runs']:
            for at, low, high, step in row['flagged']:
                print('  %s %.1f s: v %.2f..%.2f m/s, largest step %.2f m/s^2' % (row['run'], at, low, high, step))
    for injection in injections:
        events = [e for e in r['events'] if e['injection'] == injection]
        if not events:
            continue
        rows = []
        for kind in sim.ANOMALY_TYPES + ('all',):
            ev = [e for e in events if kind in ('all', e['type'])]
            caught = [e for e in ev if e['caught']]
            delays = [e['delay'] for e in caught]
            spans = [e['span'] for e in ev]
            rows.append([kind, count_of(len(caught), len(ev)),
                         sum(1 for d in delays if d <= LATENCY), '%.2f' % np.median(delays) if delays else '-',
                         '%.2f' % max(delays) if delays else '-', '%.0f%%' % (100 * np.median(spans)),
                         '%.0f%%' % (100 * min(spans)), count_of(sum(1 for s in spans if s >= MIN_SPAN_KEPT), len(ev)),
                         '%.1f' % np.median([e['length'] for e in ev])])
        common.table(['type', 'caught', 'within %gs' % LATENCY, 'median latency s', 'worst latency s',
                      'median span kept', 'least span kept', '>= 95% kept', 'median event s'], rows,
                     'injection %s (every replayed run, seeds together):' % injection)
        kept = sum(row['injected'][injection]['kept'] for row in r['runs']
                   if isinstance(row['injected'].get(injection), dict))
        need = sum(row['injected'][injection]['need'] for row in r['runs']
                   if isinstance(row['injected'].get(injection), dict))
        if need:
            print('kept/ideal over every injected run (%s): %d/%d = %.2fx (target <= 1.5x)' % (
                injection, kept, need, kept / float(need)))
    drift = r.get('drift')
    if drift:
        print('drift: place change %.1f min into the replay, %.1f min after it' % (
            drift['switch_after_s'] / 60.0, drift['after_s'] / 60.0))
        for label in ('plain', 'online'):
            d = drift[label]
            print('  %-6s before the switch %d windows (%.1f/h); drift reported %s; false windows per 5 min after the '
                  'switch %s; from 10 min after it on %d = %.1f/h (target <= 2/h)%s' % (
                      label, d['before'], d['before'] / d['before_hours'] if d['before_hours'] else 0.0,
                      'never' if not d['drift'] else '%.0f s into the replay, %.0f s %s the switch (peak %.0f%%)' % (
                          d['first_drift_into_replay'], abs(d['first_drift_after_switch']),
                          'after' if d['first_drift_after_switch'] >= 0 else 'BEFORE', 100 * (d['peak'] or 0)),
                      d['blocks'], d['late'], d['late_rate'],
                      '; online model written' if d['online'] else '')
                  + '; %.0f%% of the time after the switch inside windows' % (100 * d['kept_after']))
            for scale, a in d['adapted']:
                print('         events injected into the new place from %.0f min after the switch on, at the scale '
                      'of %s: %s' % (ADAPTED / 60.0, scale, 'not injected: %s' % a['error'] if 'error' in a else
                                     'caught %d/%d, within %.1f s %d, >= %.0f%% of the span kept %d; missed: %s' % (
                                         a['caught'], a['events'], LATENCY, a['fast'], 100 * MIN_SPAN_KEPT, a['spans'],
                                         ', '.join('%s %d' % item for item in sorted(a['missed'].items()))
                                         or 'none')))
    print('(%.0f s)\n' % r['seconds'])
    sys.stdout.flush()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--data', default=heldout_data.OUT, help='the bags of heldout_data.py (default %s)'
                        % heldout_data.OUT)
    parser.add_argument('--robots', default=','.join(heldout_data.ORDER))
    parser.add_argument('--settings', default='defaults,2s', help='of %s (default: defaults,2s)' % ', '.join(SETTINGS))
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--injection', default='robot,bwibot', help='robot, bwibot or both (default both)')
    parser.add_argument('--train-minutes', type=float, default=20.0)
    parser.add_argument('--mrclam-robots', type=int, default=2, help='MRCLAM robots replayed (1-5, default 2)')
    parser.add_argument('--no-drift', action='store_true')
    parser.add_argument('--stride', type=int, help="cclog collect's --stride (default: its own)")
    parser.add_argument('--explain', action='store_true', help='describe the driving around every false window')
    parser.add_argument('--tune', type=float, metavar='N', help='cclog tune the model to N false windows/h on the '
                        'training bags (anomalies at the first --injection scale) and replay with the tuned model')
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(',')]
    injections = args.injection.split(',')
    robots = args.robots.split(',')
    started = time.time()
    common.header('Held-out public robots: cclog collect/learn on the first %g min, replay of the rest'
                  % args.train_minutes,
                  ['data: %s (bench/HELDOUT_SOURCES.md: sources, licences, sha256)' % ', '.join(
                      '%s %s' % (os.path.basename(p), common.sha12(p)) for robot in robots
                      for p in heldout_data.runs(robot, args.data)[:args.mrclam_robots if robot == 'mrclam' else None]),
                   'seeds %s, injection %s, settings %s' % (seeds, injections, args.settings)])
    for robot in robots:
        runs = load_runs(robot, args.data, args.mrclam_robots)
        for setting in args.settings.split(','):
            tmp = tempfile.mkdtemp(prefix='cc_log_heldout_')
            try:
                report(evaluate(robot, runs, setting, seeds, injections, tmp, args.train_minutes * 60.0,
                                not args.no_drift, args.stride, args.tune), injections, args.explain)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
    print('total %.0f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())

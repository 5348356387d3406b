#!/usr/bin/env python3
"""Strong events at <= 5 false windows/h: the bound with the labels, for every detector of bench/detectors.py.

    nice -n 5 /usr/bin/python3 bench/strong_bound.py                   # seeds 0,1 and 2,3: a table each (~14 min)
    nice -n 5 /usr/bin/python3 bench/strong_bound.py --seeds 0,1       # one seed set
    /usr/bin/python3 bench/strong_bound.py --quick                     # the Husky, seed 0

Issue 45's target: pooled over >= 3 h of held-out nominal driving, <= 5 false windows/h, and every event whose
most extreme feature exceeds the robot's own nominal maximum by >= 1.5x ("strong") caught, <= 0.5 s after onset,
>= 95 % of its span kept. This asks whether any detector of the bench can meet it even with its threshold chosen
WITH the labels (an upper bound on any rule from training alone). The robots, windows, detectors, injected events,
episodes and measures are bench/detectors.py's (imported): the standard detectors, the envelope and the
combinations of bench/detector_candidates.py (``env2|maha4|lof6`` is cc_log's window rule).

A window's level: ``(zero - score) / (zero - extreme)`` (the envelope: its largest ratio), so detectors.py's rule
"flag below zero - level x (zero - extreme)" flags the windows above the level. Per event three levels, one per
demand (MEASURES): it is caught, caught within 0.5 s, or caught within 0.5 s with >= 95 % of its span kept (the
target's demand) at a level L exactly when L is below that level. Per detector and demand, each with one level
for every robot (the bench's rule) and with a level of each robot's own:

- **catching all**: the strictest level at which every strong event is caught (just below the least of their
  levels; per robot: each robot's own), the false windows per hour it then opens in the held-out nominal driving
  (95 % upper bound), the most any stricter level opens ("stricter: most", as flagging nearly everything merges
  windows into few long ones) and the share of that driving its episodes keep;
- **at <= 5/h**: loosening from the strictest level, the loosest before the pooled false windows first exceed 5
  per hour: the strong events caught (per robot: the pooled budget shared between the robots for the most events,
  each robot's level again the loosest before its own windows first exceed the budget).

"The robot's own nominal maximum" read two ways: its training driving's (floored: detectors.py's extreme) and all
its nominal driving's, training and held out. Per robot: where held-out nominal driving exceeds 1.5x the training
maximum (the envelope's episodes at 1.5x: run, time into it, the features beyond 1.5x, speed and yaw rate). One
line per reading and demand, and last per seed set the verdict: is the target (the training maximum, caught within
0.5 s with >= 95 % kept, a level per robot) met by any detector even so; "all N cost" counts the most false
windows of the cheapest detector's levels or stricter ones. Figures and what they say: docs/DETECTION.md, "Strong
events at <= 5/h: the bound with the labels".
"""
import argparse
import bisect
import collections
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
import detector_candidates  # noqa: E402
import detectors as bench  # noqa: E402
import heldout_data  # noqa: E402
from standard_detectors import WINDOW, Envelope  # noqa: E402

from cc_log import sim  # noqa: E402
from cc_log.features.envelope import ENVELOPE_COLUMNS  # noqa: E402
from cc_log.offline.tuning import windows_of  # noqa: E402

PRE, POST, LATENCY, STRONG = bench.PRE, bench.POST, bench.LATENCY, bench.STRONG
RATE = 5.0                 # false windows per hour: the target
MEASURES = (('caught', 0), ('caught within 0.5 s', 1), ('caught within 0.5 s, >= 95 % of the span kept', 2))
READINGS = (('extreme', 'the training maximum'), ('extreme_all', "all nominal driving's maximum"))
TOP = 8                    # nominal exceedances printed per robot


# -- levels --------------------------------------------------------------------------------------------------------

def levels_of(detector, scores):
    """How far each window lies past the training's typical score, in units of (zero - extreme): detectors.py
    flags a window at level L exactly when this is above L."""
    return (detector.zero - np.asarray(scores, dtype=float)) / (detector.zero - detector.extreme)


def below(level):
    """The strictest level that flags a window of ``level``."""
    return np.nextafter(level, -np.inf)


def span_level(ends, lv, entry):
    """The level below which >= MIN_SPAN_KEPT of an event's [onset, end] lies in the episodes of the flagged
    windows (inf for an event of no length, -inf when no level keeps it)."""
    if entry['end'] <= entry['start']:
        return np.inf
    near = (ends >= entry['start'] - POST) & (ends <= entry['end'] + PRE)
    order = np.argsort(-lv[near], kind='stable')
    stamps, values = ends[near][order], lv[near][order]

    def kept(k):  # the k windows of highest level flagged
        return bench.span_kept(windows_of(np.sort(stamps[:k]), PRE, POST), entry)

    if not len(stamps) or not kept(len(stamps)):
        return -np.inf
    lo, hi = 1, len(stamps)
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if kept(mid) else (mid + 1, hi)
    return values[lo - 1]


def event_levels(ends, lv, entry, reach=WINDOW):
    """(caught, caught within LATENCY, the target's demand) levels of one event: at a level L it is caught /
    caught within LATENCY / also has >= MIN_SPAN_KEPT of its span kept exactly when L is below them (-inf:
    at no level), as detectors.add_events counts it."""
    inside = (ends >= entry['start']) & (ends <= entry['end'] + reach)
    quick = inside & (ends <= entry['start'] + LATENCY)
    catch = lv[inside].max() if inside.any() else -np.inf
    fast = lv[quick].max() if quick.any() else -np.inf
    return catch, fast, min(fast, span_level(ends, lv, entry))


# -- false windows as the level falls ------------------------------------------------------------------------------

def false_windows(nominal, level):
    """Episodes (detectors.py's: windows_of) of the windows above ``level`` in nominal runs [(ends, levels)]."""
    return sum(len(windows_of(ends[lv > level], PRE, POST)) for ends, lv in nominal)


def kept_share(nominal, level):
    """The share of the nominal runs' time inside the episodes at ``level``."""
    inside = total = 0.0
    for ends, lv in nominal:
        if len(ends):
            a, b = ends[0] - WINDOW, ends[-1]
            total += b - a
            inside += sum(max(0.0, min(hi, b) - max(lo, a)) for lo, hi in windows_of(ends[lv > level], PRE, POST))
    return inside / total if total else 0.0


def false_steps(nominal):
    """The false windows of nominal runs [(ends, levels)] as the level falls, exactly: (levels, counts), levels
    descending, at a level L with levels[i + 1] <= L < levels[i] the windows above L open counts[i] episodes
    (windows_of's, run by run: one window added at a time, joining its neighbours' episodes or not)."""
    runs = np.concatenate([np.full(len(ends), k) for k, (ends, _) in enumerate(nominal)] + [np.zeros(0, int)])
    stamps = np.concatenate([ends for ends, _ in nominal] + [np.zeros(0)])
    lv = np.concatenate([values for _, values in nominal] + [np.zeros(0)])
    order = np.argsort(-lv, kind='stable')
    flagged = [[] for _ in nominal]
    levels, counts, count, at = [], [], 0, 0

    def linked(a, b):  # windows_of joins b to the episode ending at a + POST
        return b - PRE <= a + POST

    while at < len(order):
        value = lv[order[at]]
        while at < len(order) and lv[order[at]] == value:
            run, t = runs[order[at]], stamps[order[at]]
            f = flagged[run]
            j = bisect.bisect(f, t)
            p, s = (f[j - 1] if j else None), (f[j] if j < len(f) else None)
            count += 1 - (p is not None and linked(p, t)) - (s is not None and linked(t, s)) + (
                p is not None and s is not None and linked(p, s))
            f.insert(j, t)
            at += 1
        levels.append(value)
        counts.append(count)
    return np.array(levels, dtype=float), np.array(counts, dtype=float)


def at_levels(steps, level):
    """(false windows, the most false windows of it or any stricter level) at each of ``level`` (an array) from
    ``false_steps``."""
    levels, counts = steps
    level = np.atleast_1d(np.asarray(level, dtype=float))
    i = np.searchsorted(-levels, -level, 'left')    # how many step levels lie above each level
    most = np.maximum.accumulate(counts) if len(counts) else counts
    return np.concatenate([[0.0], counts])[i], np.concatenate([[0.0], most])[i]


# -- the bound -----------------------------------------------------------------------------------------------------

def catch_all(nominal, needs):
    """The strictest level catching every event of ``needs`` (their levels): (level, false windows, kept share);
    level inf when there is none to catch, -inf (false windows None) when some event is caught at no level."""
    needs = np.asarray(needs, dtype=float)
    if not len(needs):
        return np.inf, 0, 0.0
    if not np.isfinite(needs.min()):
        return -np.inf, None, 1.0
    level = below(needs.min())
    return level, false_windows(nominal, level), kept_share(nominal, level)


def options(steps, needs, budget):
    """A robot's choices at a false-window budget: [(false windows, events caught, level)] at the strict end and
    just below each event's level, while no stricter level opens more than ``budget``."""
    needs = np.asarray(needs, dtype=float)
    candidates = np.concatenate([[np.inf], below(np.unique(needs[np.isfinite(needs)]))[::-1]])
    false, worst = at_levels(steps, candidates)
    return [(int(f), int((needs > level).sum()), level) for f, w, level in zip(false, worst, candidates)
            if w <= budget]


def share_budget(choices, budget):
    """The most events a budget of false windows buys, one choice per robot (``choices``: per robot
    [(false windows, events caught, ...)], each with a choice of none)."""
    best = np.zeros(budget + 1)                      # best[b]: the most caught with at most b false windows
    for robot in choices:
        new = np.full(budget + 1, -np.inf)
        for cost, value in ((c[0], c[1]) for c in robot):
            if cost <= budget:
                new[cost:] = np.maximum(new[cost:], best[:budget + 1 - cost] + value)
        best = new
    return int(best[budget])


def pooled_steps(steps):
    """``false_steps`` of several robots' nominal runs at one level for all: their sum, a step at each of theirs."""
    points = np.unique(np.concatenate([s[0] for s in steps] + [[np.inf]]))[::-1]
    false = sum(at_levels(s, below(points))[0] for s in steps)
    return points, false


def common_level(steps, needs, budget):
    """One level for every robot (``steps`` and ``needs`` per robot): the loosest before the pooled false windows
    first exceed ``budget``: (events caught, level, false windows)."""
    pooled = np.concatenate([np.asarray(n, dtype=float) for n in needs])
    both = pooled_steps(steps)
    best = (0, np.inf, 0)
    for level in below(np.unique(pooled[np.isfinite(pooled)]))[::-1]:
        false, worst = at_levels(both, level)
        if worst[0] > budget:
            break
        best = (int((pooled > level).sum()), level, int(false[0]))
    return best


def bound(nominals, hours, steps, needs):
    """One detector's bound, per robot its nominal runs [(ends, levels)], hours of them, ``false_steps`` and the
    population's levels (``needs``): {'population', 'level', 'false', 'worst', 'kept', 'caught_at_rate',
    'rate_level', 'robot_false', 'robot_worst', 'robot_kept', 'robot_caught_at_rate'} (``robot_``: a level per
    robot; ``worst``: the most false windows of the level catching all or a stricter one)."""
    total = sum(hours)
    budget = int(math.floor(RATE * total + 1e-9))
    level, false, kept = catch_all([run for nominal in nominals for run in nominal],
                                   np.concatenate([np.asarray(n, float) for n in needs] + [[]]))
    each = [catch_all(nominal, n) for nominal, n in zip(nominals, needs)]
    robot_false = None if any(f is None for _, f, _ in each) else sum(f for _, f, _ in each)
    robot_kept = sum(k * h for (_, _, k), h in zip(each, hours)) / total if total else 0.0
    robot_worst = None if robot_false is None else sum(at_levels(s, lv)[1][0] for s, (lv, _, _) in zip(steps, each))
    caught, rate_level, _ = common_level(steps, needs, budget)
    return {'population': sum(len(n) for n in needs), 'level': level, 'false': false, 'kept': kept,
            'worst': None if false is None else at_levels(pooled_steps(steps), level)[1][0],
            'caught_at_rate': caught, 'rate_level': rate_level, 'robot_false': robot_false, 'robot_kept': robot_kept,
            'robot_worst': robot_worst,
            'robot_caught_at_rate': share_budget([options(s, n, budget) for s, n in zip(steps, needs)], budget)}


def met_line(bounds, population, hours, what='target strong events'):
    """The verdict line: ``bounds`` {detector: bound} of the strong events (``population`` of them) over
    ``hours`` of held-out nominal driving: met when one catches them all at <= RATE (a level per robot), the best
    the most; catching them all costs the cheapest the most false windows of its levels or stricter ones."""
    costs = {name: b['robot_worst'] for name, b in bounds.items() if b['robot_worst'] is not None}
    best = max(bounds, key=lambda name: (bounds[name]['robot_caught_at_rate'], -costs.get(name, np.inf)))
    cheapest = min(costs, key=costs.get) if costs else None
    met = bounds[best]['robot_caught_at_rate'] >= population
    return '%s at <= %g/h: %s by any detector (best: %s, %d/%d at <= %g/h; all %d cost %s)' % (
        what, RATE, 'met' if met else 'not met', best, bounds[best]['robot_caught_at_rate'], population, RATE,
        population, '%.1f/h (%s)' % (costs[cheapest] / hours, cheapest) if cheapest
        else 'never (no level catches them all)')


# -- one robot -----------------------------------------------------------------------------------------------------

def evaluate(robot, runs, seeds, train_seconds, fraction):
    """Every detector's window levels in the held-out nominal driving of one robot and every injected event's
    levels: {'robot', 'hours', 'nominal' {detector: [(ends, levels)]}, 'events' [{type, run, seed, at, extreme,
    feature, extreme_all, feature_all, need {detector: (caught, within 0.5 s, target)}}], 'exceed'}."""
    started = time.time()
    train, rest, scale, detectors, X = bench.fitted(runs, train_seconds, fraction, candidates=True)
    out = {'robot': robot, 'hours': sum(bench.duration(r) for _, r in rest) / 3600.0,
           'train_minutes': sum(bench.duration(r) for _, r in train) / 60.0,
           'nominal': {name: [] for name in detectors}, 'events': [], 'exceed': []}
    held = [bench.windows(records) for _, records in rest]
    everything = Envelope().fit(np.concatenate([X] + [M for _, M in held if len(M)]))
    for (name, records), (ends, M) in zip(rest, held):
        for label, detector in detectors.items():
            levels = levels_of(detector, detector_candidates.part_score(detector, M, ends))
            out['nominal'][label].append((ends, levels))
        out['exceed'] += exceedances(detectors['envelope'], ends, M, name, records[0].stamp)
        for seed in seeds:
            for injected, truth in bench.injections(records, seed, scale):
                ends, M = bench.windows(injected)
                events = [{'type': e['type'], 'run': name, 'seed': seed, 'at': e['start'] - records[0].stamp,
                           'need': {}} for e in truth]
                for event, entry in zip(events, truth):
                    event['extreme'], event['feature'] = bench.extreme_of(detectors['envelope'], ends, M, entry)
                    event['extreme_all'], event['feature_all'] = bench.extreme_of(everything, ends, M, entry)
                for label, detector in detectors.items():
                    lv = levels_of(detector, detector_candidates.part_score(detector, M, ends))
                    for event, entry in zip(events, truth):
                        event['need'][label] = event_levels(ends, lv, entry)
                out['events'] += events
    out['seconds'] = time.time() - started
    return out


def exceedances(envelope, ends, M, run, t0):
    """The envelope's episodes at STRONG x in a nominal run (detectors.episodes_of): {'run', 'start', 'end' (s into
    the run), 'why' (the most outstanding feature), 'ratio' (its), 'beyond' (every feature beyond STRONG x in it),
    'speed', 'yaw_rate' (the most in it: what the robot was doing)}."""
    out = []
    for _, _, start, end, why in bench.episodes_of(envelope, ends, M, run, t0, STRONG):
        inside = (ends - t0 >= start) & (ends - t0 <= end)
        most = envelope.ratios(M[inside]).max(axis=0)
        out.append({'run': run, 'start': start, 'end': end, 'why': why, 'ratio': float(most.max()),
                    'beyond': [c for c, ratio in zip(ENVELOPE_COLUMNS, most) if ratio > STRONG],
                    'speed': float(M[inside, ENVELOPE_COLUMNS.index('max_speed')].max()),
                    'yaw_rate': float(M[inside, ENVELOPE_COLUMNS.index('max_yaw_rate')].max())})
    return out


def report_robot(r):
    """Where the robot's held-out nominal driving exceeds 1.5x its training maximum."""
    episodes = r['exceed']
    print('## %s: trained on %.1f min, held out %.1f min of nominal driving, %d events injected (%.0f s)' % (
        r['robot'], r['train_minutes'], r['hours'] * 60.0, len(r['events']), r['seconds']))
    features = collections.Counter(e['why'].split()[0] for e in episodes)
    print('held-out nominal driving beyond %gx its training maximum: %d episodes (%.1f/h); by the most outstanding '
          'feature: %s' % (STRONG, len(episodes), len(episodes) / r['hours'] if r['hours'] else float('nan'),
                           ', '.join('%s %d' % item for item in features.most_common()) or '-'))
    for e in sorted(episodes, key=lambda e: -e['ratio'])[:TOP]:
        print('  %s %7.1f-%7.1f s into its held-out part: %s; beyond %gx: %s; up to %.2f m/s, %.2f rad/s' % (
            e['run'], e['start'], e['end'], e['why'], STRONG, ', '.join(e['beyond']), e['speed'], e['yaw_rate']))
    print()
    sys.stdout.flush()


# -- report --------------------------------------------------------------------------------------------------------

def needs_of(results, name, reading, measure, seeds):
    """Per robot the levels of the strong events (``reading``: 'extreme' or 'extreme_all') of ``seeds``."""
    return [[e['need'][name][measure] for e in r['events'] if e['seed'] in seeds and e[reading] >= STRONG]
            for r in results]


def per_hour(count, hours):
    """'rate (its 95 % upper bound)' of a count of false windows in ``hours``; '-' for none."""
    return '-' if count is None else '%.1f (%.1f)' % (count / hours, bench.upper95(count, hours))


def rate(count, hours):
    return '-' if count is None else '%.1f' % (count / hours)


def bounds_of(results, names, steps, reading, measure, seeds):
    """{detector: bound} of the strong events (``reading``) of ``seeds`` at ``measure`` (an index of MEASURES')."""
    return collections.OrderedDict(
        (name, bound([r['nominal'][name] for r in results], [r['hours'] for r in results],
                     [steps[r['robot']][name] for r in results], needs_of(results, name, reading, measure, seeds)))
        for name in names)


def report_seed_set(results, names, steps, seeds):
    """The tables of one seed set, one line per reading and measure, and the verdict line."""
    hours = sum(r['hours'] for r in results)
    events = [e for r in results for e in r['events'] if e['seed'] in seeds]
    print('## Seeds %s: pooled over %d robots, %.2f h of held-out nominal driving (<= %g/h: at most %d false '
          'windows), %d events' % (','.join(map(str, seeds)), len(results), hours, RATE,
                                   int(math.floor(RATE * hours + 1e-9)), len(events)))
    for reading, what in READINGS:
        strong = [e for e in events if e[reading] >= STRONG]
        print('strong (>= %gx %s): %d events; per type %s' % (STRONG, what, len(strong), ' '.join(
            '%s %d/%d' % (bench.SHORT[kind], sum(e['type'] == kind for e in strong),
                          sum(e['type'] == kind for e in events)) for kind in sim.ANOMALY_TYPES)))
    both = sum(e['extreme'] >= STRONG and e['extreme_all'] >= STRONG for e in events)
    print('strong both ways: %d; by the training maximum only: %d; by all nominal driving only: %d\n' % (
        both, sum(e['extreme'] >= STRONG for e in events) - both,
        sum(e['extreme_all'] >= STRONG for e in events) - both))
    lines = []
    for reading, what in READINGS:
        for label, measure in MEASURES:
            bounds = bounds_of(results, names, steps, reading, measure, seeds)
            population = next(iter(bounds.values()))['population']
            rows = [[name, '%.3g' % b['level'], per_hour(b['false'], hours), rate(b['worst'], hours),
                     '%.0f%%' % (100 * b['kept']), '%d/%d (%.3g)' % (b['caught_at_rate'], population, b['rate_level']),
                     per_hour(b['robot_false'], hours), rate(b['robot_worst'], hours),
                     '%.0f%%' % (100 * b['robot_kept']), '%d/%d' % (b['robot_caught_at_rate'], population)]
                    for name, b in bounds.items()]
            common.table(['detector', 'one level: catching all at', 'false/h (95% upper)', 'stricter: most /h',
                          'nominal kept', 'at <= %g/h: caught (level)' % RATE,
                          'a level per robot: catching all, false/h', 'stricter: most /h', 'nominal kept',
                          'at <= %g/h: caught' % RATE], rows,
                         'seeds %s, strong = >= %gx %s (%d events), %s, the threshold chosen with the labels:' % (
                             ','.join(map(str, seeds)), STRONG, what, population, label))
            report_robots(results, names, steps, reading, measure, seeds)
            lines.append(met_line(bounds, population, hours, 'strong (>= %gx %s) %s' % (STRONG, what, label)))
            if (reading, measure) == (READINGS[0][0], MEASURES[-1][1]):
                verdict = met_line(bounds, population, hours)
    print('\n'.join(lines))
    print(verdict + ' (seeds %s; %s; a level per robot chosen with the labels)\n' % (
        ','.join(map(str, seeds)), MEASURES[-1][0]))
    sys.stdout.flush()


def report_robots(results, names, steps, reading, measure, seeds):
    """Per robot: the false windows that catching every strong event there (at ``measure``) costs, with the
    share of its nominal driving kept; the cheapest detector by the most false windows of that level or a stricter
    one (flagging nearly everything opens few, long windows)."""
    rows = []
    for r in results:
        cost, worst = {}, {}
        for name in names:
            level, false, kept = catch_all(r['nominal'][name], needs_of([r], name, reading, measure, seeds)[0])
            if false is not None:
                cost[name] = '%d (%.0f%%)' % (false, 100 * kept)
                worst[name] = at_levels(steps[r['robot']][name], level)[1][0]
        cheapest = min(worst, key=worst.get) if worst else None
        rows.append([r['robot'], '%.1f' % (r['hours'] * 60), len(needs_of([r], names[0], reading, measure, seeds)[0])]
                    + [cost.get(name, '-') for name in ('envelope', 'env2|maha4|lof6')]
                    + ['%s: %s' % (cheapest, cost[cheapest]) if cheapest else '-'])
    common.table(['robot', 'held-out nominal min', 'strong events', 'envelope', 'env2|maha4|lof6', 'cheapest'], rows,
                 'per robot, false windows (nominal driving kept) of catching every strong event there, %s, '
                 'its own level:' % dict((m, label) for label, m in MEASURES)[measure])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--data', default=heldout_data.OUT, help='the held-out bags (default %s)' % heldout_data.OUT)
    parser.add_argument('--robots', default=','.join(bench.ROBOTS), help='of %s' % ', '.join(bench.ROBOTS))
    parser.add_argument('--seeds', nargs='+', default=['0,1', '2,3'], help='seed sets, a table each (default 0,1 2,3)')
    parser.add_argument('--train-minutes', type=float, default=20.0)
    parser.add_argument('--train-fraction', type=float, default=0.5)
    parser.add_argument('--quick', action='store_true', help='the Husky alone, seed 0')
    args = parser.parse_args(argv)
    robots = ['husky'] if args.quick else args.robots.split(',')
    sets = [[0]] if args.quick else [[int(s) for s in group.split(',')] for group in args.seeds]
    for robot in robots:
        if robot not in bench.ROBOTS:
            raise SystemExit('robots: unknown robot %r (choose from %s)' % (robot, ', '.join(bench.ROBOTS)))
    started = time.time()
    paths = [p for robot in robots if robot in heldout_data.ORDER for p in heldout_data.runs(robot, args.data)]
    paths += [bench.detection_runs.bag_path(name) for robot in robots if robot in bench.REAL
              for name in bench.detection_runs.ROBOTS[robot]]
    common.header('Strong events at <= %g false windows/h: the bound with the labels' % RATE, [
        'data: %s (bench/HELDOUT_SOURCES.md, ../shared/data/real/SOURCES.md)' % ', '.join(
            '%s %s' % (os.path.basename(p), common.sha12(p)) for p in paths),
        'seed sets %s; windows %g s every %g s; train the first %g min, at most %g of a robot (bench/detectors.py)'
        % (sets, WINDOW, bench.STRIDE, args.train_minutes, args.train_fraction)])
    seeds = sorted(set(s for group in sets for s in group))
    results = []
    for robot in robots:
        results.append(evaluate(robot, bench.load_robot(robot, args.data), seeds, args.train_minutes * 60.0,
                                args.train_fraction))
        report_robot(results[-1])
    names = list(results[0]['nominal'])
    steps = {r['robot']: {name: false_steps(r['nominal'][name]) for name in names} for r in results}
    for group in sets:
        report_seed_set(results, names, steps, group)
    print('total %.0f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())

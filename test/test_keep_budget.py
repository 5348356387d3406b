"""The keep budget (``max_windows_per_hour``): a rising threshold over a sliding hour of message time.

Pure: the decisions of ``logger.keep_budget.KeepBudget`` on Fires of known scores, the option and its checks, what
/diagnostics says. End to end: ``cclog replay`` of the real Husky bag with a model learnt on its first half, with
and without a budget: the windows kept are the ones the rule keeps (by the scores in their metadata) and the
summary counts and names the one it skipped.
"""
import json
import math
import os
import sys

import pytest

from cc_log.logger import config, health, options
from cc_log.logger.keep_budget import DRIFT_HINT, KeepBudget
from cc_log.triggers.base import Fire, Trigger

HUSKY = 'husky_outdoor_2015.bag'
HUSKY_ODOM = '/husky_velocity_controller/odom'
NAN = float('nan')


def fire(score, name='classifier'):
    return Fire(name, name, score)


def decisions(budget, fires):
    """``admit`` of each ``(stamp, score)`` in turn (each opening a window)."""
    return [budget.admit(stamp, fire(score)) for stamp, score in fires]


# -- the rule -------------------------------------------------------------------------------------------------

def test_past_the_budget_only_a_score_below_the_hours_kth_best_opens_and_the_skipped_are_counted():
    budget = KeepBudget(2)
    fires = [(0, -1.0), (10, -5.0), (20, -2.0), (30, -10.0), (40, -3.0), (50, -4.0), (60, -20.0)]
    # -1, -5: within the budget. -2 < -1 (the 2nd best of {-1, -5}): opens. -10 < -2 (2nd best of {-1, -5, -2}):
    # opens. -3 and -4 are not below -5 (2nd best of {-1, -5, -2, -10}): skipped. -20 < -5: opens.
    assert decisions(budget, fires) == [True, True, True, True, False, False, True]
    stats = budget.stats()
    assert stats['windows_skipped'] == 2
    assert stats['skipped_scores'] == [-3.0, -4.0]
    assert [(s['stamp'], s['trigger'], s['score']) for s in stats['skipped']] == [
        (40, 'classifier', -3.0), (50, 'classifier', -4.0)]
    assert stats['skipped_score_range'] == (-4.0, -3.0)
    assert stats['keep_threshold'] == -10.0  # the 2nd best of the hour now
    assert stats['max_windows_per_hour'] == 2.0


def test_a_score_equal_to_the_threshold_is_not_more_anomalous():
    budget = KeepBudget(1)
    assert decisions(budget, [(0, -2.0), (10, -2.0), (20, -2.0000001)]) == [True, False, True]


def test_the_hour_slides_in_message_time():
    budget = KeepBudget(2)
    assert decisions(budget, [(0, -9.0), (10, -9.0), (3599, -1.0)]) == [True, True, False]
    # at 3605 the window of 0 is more than an hour old: one of two is left, anything opens
    assert decisions(budget, [(3605, -0.5)]) == [True]
    # {-9 at 10, -0.5 at 3605}: spent again, the threshold is -0.5
    assert decisions(budget, [(3606, -0.4), (3607, -0.6)]) == [False, True]
    # an hour after every window: the budget is fresh, whatever the score
    assert decisions(budget, [(7300, 100.0), (7301, 100.0), (7302, 100.0)]) == [True, True, False]


def test_extending_an_open_window_is_never_refused_and_lowers_its_score():
    budget = KeepBudget(1)
    assert budget.admit(0, fire(-1.0))
    assert budget.admit(1, fire(50.0), opens=False)   # the same event: admitted though the budget is spent
    assert budget.admit(2, fire(-8.0), opens=False)   # the window's score is now -8
    assert not budget.admit(100, fire(-5.0))           # -5 is not below -8
    assert budget.admit(200, fire(-9.0))
    assert budget.stats()['windows_skipped'] == 1


def test_fires_without_a_score_always_open_and_count_against_the_budget():
    budget = KeepBudget(1)
    assert decisions(budget, [(0, -1.0), (10, NAN), (20, None)]) == [True, True, True]
    # two windows without a score rank as the most anomalous: no scored Fire beats them this hour
    assert decisions(budget, [(30, -1e9)]) == [False]
    budget = KeepBudget(2)
    assert decisions(budget, [(0, NAN), (10, NAN), (20, -1e9), (30, NAN)]) == [True, True, False, True]


def test_refused_fires_close_together_are_one_skipped_window_and_one_in_a_windows_pre_is_none():
    budget = KeepBudget(1, pre=2.0, post=2.0)  # Fires less than 4 s apart would have made one window
    assert budget.admit(0, fire(-10.0))
    assert decisions(budget, [(10, -1.0), (12, -3.0), (15.5, -2.0)]) == [False, False, False]
    assert decisions(budget, [(30, -4.0)]) == [False]
    stats = budget.stats()
    assert stats['windows_skipped'] == 2
    assert stats['skipped_scores'] == [-3.0, -4.0]  # a skipped window's score: the lowest of its Fires
    assert [s['stamp'] for s in stats['skipped']] == [10, 30]
    assert stats['skipped_score_range'] == (-4.0, -3.0)
    # refused at 40, then a window opens at 41.5 (its 2 s pre holds 40): the event was kept, not skipped
    assert decisions(budget, [(40, -5.0), (41.5, -11.0)]) == [False, True]
    assert budget.stats()['windows_skipped'] == 2


def test_time_jumping_back_starts_the_budget_afresh():
    budget = KeepBudget(1)
    assert decisions(budget, [(1000, -1.0), (1010, -0.5), (5, -0.5)]) == [True, False, True]


def test_a_fraction_of_a_window_per_hour_is_one_window_per_so_many_hours():
    budget = KeepBudget(0.5)  # one window per 2 h
    assert decisions(budget, [(0, -1.0), (3700, 0.0), (7300, 0.0)]) == [True, False, True]
    budget = KeepBudget(2.5)  # 3 windows per 72 min
    assert (budget.count, budget.span) == (3, pytest.approx(72 * 60.0))


def test_no_budget_admits_everything_and_counts_nothing():
    budget = KeepBudget(0)
    assert decisions(budget, [(t, 0.0) for t in range(100)]) == [True] * 100
    stats = budget.stats()
    assert stats['windows_skipped'] == 0 and stats['keep_threshold'] is None


# -- the option ------------------------------------------------------------------------------------------------

def test_the_option_is_declared_once_for_the_node_replay_and_the_configuration():
    option = options.get('max_windows_per_hour')
    assert option.key == 'limits.max_windows_per_hour' and option.default == 0.0
    assert 'smart' in option.nodes and 'replay' in option.commands
    assert option.parse('2') == 2.0 and option.parse(0.1) == 0.1
    cfg = config.Config.from_dict({'limits': {'max_windows_per_hour': 6}})
    assert cfg.max_windows_per_hour == 6.0
    assert config.Config.from_dict({}).max_windows_per_hour == 0.0


@pytest.mark.parametrize('value', [-1, 'often', 3601, True, 'nan', [2]])
def test_a_bad_budget_is_one_line_naming_the_key(value):
    with pytest.raises(ValueError) as error:
        config.Config.from_dict({'limits': {'max_windows_per_hour': value}}, 'robot.yaml')
    assert str(error.value).startswith('robot.yaml: limits.max_windows_per_hour: ')
    assert '\n' not in str(error.value)
    with pytest.raises(ValueError, match='^max_windows_per_hour: '):
        KeepBudget(value)


def test_diagnostics_warn_once_windows_are_skipped_with_their_count_and_scores():
    budget = KeepBudget(1)
    decisions(budget, [(0, -3.0)])
    assert health.skipped(budget.stats()) == []
    assert health.skipped_value(budget.stats()) == '0'
    assert health.skipped_value(KeepBudget(0).stats()) == '0 (no keep budget)'
    decisions(budget, [(100, -1.0), (200, -2.5)])
    [(level, text)] = health.skipped(budget.stats())
    assert level == health.WARN
    assert text == '2 window(s) skipped (keep budget 1/h; scores -2.5 .. -1): ' + DRIFT_HINT
    assert "the robot's normal may have drifted (cclog replay reports drift)" in text
    assert health.skipped_value(budget.stats()) == '2 (scores -2.5 .. -1)'


# -- in the smart logger ------------------------------------------------------------------------------------------

class ScoreAt(Trigger):
    """Fires with ``scores[stamp]`` at the odometry message of each of those stamps."""

    kind = 'score_at'

    def __init__(self, scores):
        super(ScoreAt, self).__init__('scored')
        self.topics = frozenset(['/odom'])
        self.scores = dict(scores)

    def on_record(self, record):
        stamp = round(record.stamp, 3)
        return [self.fire('scored', self.scores[stamp])] if stamp in self.scores else []


def odom_msg(stamp):
    from nav_msgs.msg import Odometry
    msg = Odometry()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9))
    msg.pose.pose.orientation.w = 1.0
    return msg


def test_the_smart_logger_opens_only_what_the_budget_admits_and_says_what_it_skipped(tmp_path):
    from cc_log.base.event_kinds import OPENED
    from cc_log.logger.smart import SmartLogger
    from cc_log.storage import log_format
    # 10.5 extends the window of 10 (never refused, though +5 is far from anomalous)
    scores = {10.0: -1.0, 10.5: 5.0, 30.0: -0.5, 50.0: -2.0, 70.0: -1.5, 90.0: -3.0}
    logger = SmartLogger(None, str(tmp_path), fmt='json-xz', pre='2s', post='2s', driving_topic='/odom',
                         triggers=[ScoreAt(scores)], background=False, max_windows_per_hour=1)
    opened = []
    logger.on_event(lambda event: opened.append(event.score) if event.kind == OPENED else None)
    for step in range(1000):  # 100 s at 10 Hz
        logger.on_message('/odom', odom_msg(step / 10.0), step / 10.0)
    logger.close()
    # -1 opens; -0.5 is not below -1; -2 < -1 opens; -1.5 is not below -2; -3 < -2 opens
    assert opened == [-1.0, -2.0, -3.0]
    windows = [log_format.read_metadata(path) for path in log_format.window_files(str(tmp_path))]
    windows.sort(key=lambda metadata: metadata['triggers'][0]['stamp'])
    assert [[t['score'] for t in w['triggers']] for w in windows] == [[-1.0, 5.0], [-2.0], [-3.0]]
    stats = logger.stats()
    assert stats['windows_opened'] == 3 and stats['windows_skipped'] == 2
    assert stats['skipped_scores'] == [-0.5, -1.5]
    assert [(s['stamp'], s['trigger']) for s in stats['skipped']] == [(30.0, 'scored'), (70.0, 'scored')]
    [(level, text)] = health.skipped(stats)
    assert level == health.WARN and text.startswith('2 window(s) skipped (keep budget 1/h; scores -1.5 .. -0.5): ')


# -- end to end: cclog replay of a real bag ---------------------------------------------------------------------

@pytest.fixture(scope='module')
def husky_model(tmp_path_factory):
    """A model of the Husky's driving learnt on the first half of its bag."""
    from conftest import real_data
    from cc_log.learning import learning
    from cc_log.features import FeatureConfig
    from cc_log.storage.bag import bagio
    feature = FeatureConfig('motion', '2s')
    _, vectors = bagio.feature_vectors(real_data(HUSKY), HUSKY_ODOM, feature)
    model, _ = learning.train(vectors[:len(vectors) // 2], config=feature)
    return model.save(str(tmp_path_factory.mktemp('husky') / 'husky.model.json'))


def replay(bag, model, out, *flags):
    from conftest import cclog
    result = cclog('replay', bag, '--topic', HUSKY_ODOM, '--model', model, '--out', out, *flags)
    assert result.returncode == 0, result.stderr
    return result.stdout


def window_scores(paths):
    """Per window file: (stamp and score of the Fire that opened it, the window's score: its lowest)."""
    from cc_log.storage import log_format
    found = []
    for path in paths:
        triggers = log_format.read_metadata(path)['triggers']
        scores = [t['score'] for t in triggers if t['score'] is not None and not math.isnan(t['score'])]
        found.append((triggers[0]['stamp'], triggers[0]['score'], min(scores)))
    return sorted(found)


def test_replay_with_a_budget_keeps_the_most_anomalous_windows_and_counts_the_rest(real_bag, husky_model, tmp_path):
    bag = real_bag(HUSKY)
    free = json.loads(replay(bag, husky_model, tmp_path / 'free', '--json'))
    budgeted = json.loads(replay(bag, husky_model, tmp_path / 'kept', '--max-windows-per-hour', '2', '--json'))
    assert free['keep_budget']['windows_skipped'] == 0
    k = 2
    kept = window_scores([w['path'] for w in budgeted['windows']])
    skipped = budgeted['keep_budget']
    assert k < len(kept) < len(free['windows'])  # the bag lasts minutes: one sliding hour
    # every window past the budget opened with a score below the k-th best window kept before it
    for index in range(k, len(kept)):
        best = sorted(window for _, _, window in kept[:index])
        assert kept[index][1] < best[k - 1], (index, kept)
    # every skipped window scored no better than the k-th best window kept before it
    assert skipped['windows_skipped'] == len(skipped['skipped']) >= 1
    for skip in skipped['skipped']:
        best = sorted(window for stamp, _, window in kept if stamp < skip['stamp'])
        assert len(best) >= k and skip['score'] >= best[k - 1], (skip, kept)
        # it is a window the replay without a budget kept, and no window of the budgeted one holds it
        assert any(w['start'] <= skip['stamp'] <= w['end'] for w in free['windows'])
        assert not any(w['start'] <= skip['stamp'] <= w['end'] for w in budgeted['windows'])
    # nothing else was lost: each window without a budget is kept or counted as skipped
    assert len(kept) + skipped['windows_skipped'] == len(free['windows'])
    low, high = skipped['skipped_score_range']
    assert low == min(skipped['skipped_scores']) and high == max(skipped['skipped_scores'])
    # the text summary says it the same way
    text = replay(bag, husky_model, tmp_path / 'text', '--max-windows-per-hour', '2')
    assert '%d window(s) skipped (keep budget 2/h; scores %.3g .. %.3g): %s' % (
        skipped['windows_skipped'], low, high, DRIFT_HINT) in text
    for skip in skipped['skipped']:
        assert 'skipped  %.3f  classifier  score %.4g' % (skip['stamp'], skip['score']) in text


def test_replay_refuses_a_bad_budget_in_one_line(real_bag, husky_model, tmp_path):
    from conftest import cclog
    result = cclog('replay', real_bag(HUSKY), '--topic', HUSKY_ODOM, '--model', husky_model, '--out',
                   tmp_path / 'x', '--max-windows-per-hour', '-3')
    assert result.returncode != 0
    assert 'max-windows-per-hour' in result.stderr and len(result.stderr.strip().splitlines()) <= 2
    assert not os.path.exists(tmp_path / 'x')


if __name__ == '__main__':
    sys.exit(pytest.main([__file__]))

"""``cclog plot`` with true events, and the plot module's readers (real bags, real window files)."""
import json

from cc_log.offline import plot

from test_cli import fails, ok, ok_json, replayed, trained  # noqa: F401 (fixtures)


def test_plot_draws_the_true_events_and_counts_those_inside_windows(replayed, trained, tmp_path):  # noqa: F811
    windows = replayed['summary']['windows']
    inside = windows[0]
    truth = tmp_path / 'truth.json'
    before = min(w['start'] for w in windows) - 100.0
    truth.write_text(json.dumps([{'type': 'collision', 'start': inside['start'], 'end': inside['start'] + 0.5},
                                 {'type': 'missed', 'start': before, 'end': before + 1.0}]))
    png = tmp_path / 'why.png'
    result = ok_json('plot', replayed['out'], '--bag', replayed['bag'], '--model', trained['model'],
                     '--truth', truth, '--out', png)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert (result['truth'], result['truth_in_windows']) == (2, 1)
    assert result['start'] == before  # the timeline reaches back to the earliest true event
    text = ok('plot', replayed['out'], '--truth', truth, '--out', tmp_path / 'w.png')
    assert '1 of 2 true events inside windows' in text


def test_a_bad_truth_file_is_one_line(replayed, tmp_path):  # noqa: F811
    bad = tmp_path / 'bad.json'
    bad.write_text('{"anomalies": [{"type": "x"}]}')
    line = fails('plot', replayed['out'], '--truth', bad, '--out', tmp_path / 'x.png')
    assert str(bad) in line and 'not a truth file' in line
    line = fails('plot', replayed['out'], '--truth', tmp_path / 'none.json', '--out', tmp_path / 'x.png')
    assert 'none.json' in line


def test_trigger_scores_and_threshold_come_from_the_window_metadata():
    windows = [('a', {'triggers': [{'stamp': 1.0, 'score': -2.0}, {'stamp': 2.0}], 'threshold': -1.5}, []),
               ('b', {'triggers': None}, [])]
    assert plot.trigger_scores(windows) == ([(1.0, -2.0)], -1.5)


class _Record(object):
    def __init__(self, stamp):
        self.stamp = stamp


def test_drawing_yaw_rate_seconds_from_start_legend_off_the_data_window_kinds():
    """Three panels (speed, yaw rate, score); x in seconds from the start; every legend right of its panel;
    a classifier window filled, a manual one hatched."""
    t0 = 1432236698.0
    motion = [(t0 + i * 0.1, 1.0, 0.5 * (i % 7)) for i in range(200)]
    windows = [('c', {'triggers': [{'stamp': t0 + 5, 'reason': 'classifier', 'score': -2.0}], 'threshold': -1.0},
                [_Record(t0 + 4), _Record(t0 + 7)]),
               ('m', {'triggers': [{'stamp': t0 + 12, 'reason': 'operator saw it', 'name': 'manual',
                                    'score': None}]}, [_Record(t0 + 11), _Record(t0 + 13)])]
    figure, summary = plot.draw(windows, motion, speed_label='speed (/odom)')
    axes = figure.axes
    assert [axis.get_ylabel() for axis in axes] == ['speed (m/s)', 'yaw rate (rad/s)', 'score']
    assert axes[1].lines[0].get_ydata()[3] == 1.5  # the yaw rate drawn
    assert axes[0].lines[0].get_xdata()[0] == 0.0 and summary['start'] == t0
    assert axes[-1].get_xlabel() == 'seconds from the start (2015-05-21 19:31:38 UTC)'
    figure.canvas.draw()
    for axis in axes:
        legend = axis.get_legend()
        assert legend is not None
        assert legend.get_window_extent().x0 >= axis.get_window_extent().x1  # right of the data
    labels = axes[0].get_legend_handles_labels()[1]
    assert 'classifier window' in labels and 'manual window' in labels
    spans = {patch.get_label(): patch for patch in axes[0].patches}
    assert spans['manual window'].get_hatch() == '//' and not spans['classifier window'].get_hatch()
    assert plot.window_kind({'triggers': [{'stamp': 1.0, 'reason': 'x > 2'}]}) == 'other'


def test_trigger_markers_are_drawn_above_the_score_curve_threshold_and_windows():
    t0 = 1600000000.0
    windows = [('c', {'triggers': [{'stamp': t0 + 5, 'reason': 'classifier', 'score': -2.0}], 'threshold': -1.0},
                [_Record(t0 + 4), _Record(t0 + 7)])]
    curve = [(t0 + i * 0.5, -2.0 + 0.01 * i) for i in range(40)]
    figure, _ = plot.draw(windows, [(t0 + i * 0.1, 1.0) for i in range(100)], curve)
    bottom = figure.axes[-1]
    [markers] = [line for line in bottom.lines if line.get_label() == 'trigger score']
    others = [artist for artist in bottom.lines + bottom.patches + bottom.collections if artist is not markers]
    assert {line.get_label() for line in bottom.lines} >= {'score', 'threshold -1'}
    assert others and all(markers.get_zorder() > artist.get_zorder() for artist in others)

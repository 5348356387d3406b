"""``cclog plot`` with true events, and the plot module's readers (real bags, real window files)."""
import json

from cc_log import plot

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

"""Hostile input is bounded where it enters (issue 29): each example fails with one short line naming the
input, in bounded time and memory, never a traceback."""
import pytest

from cc_log import config, safe_input
from cc_log.config import Config


def one_line(error, limit=300):
    """The text of ``error``, checked to be one short line."""
    text = str(error.value)
    assert '\n' not in text and len(text) <= limit, text[:400]
    return text


# -- 11: YAML alias bombs and unbounded reprs --------------------------------------------------------------

def alias_bomb(levels, key='driving_topic'):
    """A YAML document of a few hundred bytes whose ``key`` expands to 9 ** levels strings."""
    lines = ['a0: &a0 [%s]' % ', '.join(['lol'] * 9)]
    for level in range(1, levels):
        lines.append('a%d: &a%d [%s]' % (level, level, ', '.join(['*a%d' % (level - 1)] * 9)))
    lines.append('%s: *a%d' % (key, levels - 1))
    return '\n'.join(lines) + '\n'


def test_yaml_alias_bomb_is_refused_with_one_line(tmp_path):
    path = tmp_path / 'bomb.yaml'
    path.write_text(alias_bomb(7))
    assert path.stat().st_size < 500
    with pytest.raises(ValueError) as error:
        Config.from_dict(config.load_file(str(path)), str(path))
    assert one_line(error).startswith('%s: not YAML: YAML aliases expand' % path)


def test_yaml_too_many_aliases_is_refused(tmp_path):
    path = tmp_path / 'aliases.yaml'
    path.write_text('a: &a x\nb: [%s]\n' % ', '.join(['*a'] * (safe_input.MAX_YAML_ALIASES + 1)))
    with pytest.raises(ValueError) as error:
        config.load_file(str(path))
    assert 'more than %d YAML aliases' % safe_input.MAX_YAML_ALIASES in one_line(error)


def test_yaml_recursive_alias_is_refused(tmp_path):
    path = tmp_path / 'loop.yaml'
    path.write_text('topics: &a [*a]\n')
    with pytest.raises(ValueError) as error:
        config.load_file(str(path))
    assert 'contains it' in one_line(error)


def test_yaml_anchors_of_an_ordinary_configuration_still_load(tmp_path):
    path = tmp_path / 'robot.yaml'
    path.write_text('hold: &hold {hold_off: 3s}\n'
                    'triggers:\n  - {name: a, kind: rule, topic: /bumper, arrival: true}\n'
                    '  - {<<: *hold, name: b, kind: rule, topic: /scan, silent: 1s}\n')
    data = config.load_file(str(path))
    assert data['triggers'][1]['hold_off'] == '3s'
    del data['hold']
    cfg = Config.from_dict(data, str(path))
    assert [entry['name'] for entry in cfg.triggers] == ['a', 'b']


@pytest.mark.parametrize('document', [
    {'driving_topic': ['x' * 100000] * 50},
    {'topics': [[list(range(100000))]]},
    {'triggers': 'y' * 1000000},
    {'windows': {'pre': 'z' * 1000000}},
    {'triggers': [{'name': 'n' * 1000000, 'kind': 'rule'}]},
    {'triggers': [{'name': 'r', 'kind': 'k' * 1000000}]},
    {'k' * 1000000: 1},
])
def test_errors_show_a_bounded_part_of_the_value(document):
    with pytest.raises(ValueError) as error:
        Config.from_dict(document, 'robot.yaml')
    assert one_line(error).startswith('robot.yaml: ')


@pytest.mark.parametrize('options', [{'when': 'q' * 10 ** 6}, {'when': 'a.b > ' + 'v' * 10 ** 6},
                                     {'level': ['E'] * 10 ** 6}, {'silent': 's' * 10 ** 6},
                                     {'min_rate': 'm' * 10 ** 6}])
def test_rule_errors_show_a_bounded_part_of_the_value(options):
    from cc_log.triggers import RuleTrigger
    with pytest.raises(ValueError) as error:
        RuleTrigger('r', topic='/a', **options)
    assert one_line(error).startswith('r: ')


def test_brief_is_bounded():
    assert len(safe_input.brief('x' * 10 ** 6)) <= safe_input.BRIEF_CHARS
    assert len(safe_input.brief([[list(range(10 ** 5))] * 10 ** 3])) <= safe_input.BRIEF_CHARS
    assert safe_input.brief('/odom') == "'/odom'"

"""Options declared once (cc_log.logger.options): the configuration, the nodes' parameters, cclog's flags and
docs/OPTIONS.md all come from the declarations; one grammar for sizes and durations (cc_log.base.spans)."""
import argparse
import os
import re
import subprocess
import sys

import pytest

from cc_log.logger import config, options
from cc_log.base import spans

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_docs_options_page_is_generated_from_the_declarations():
    result = subprocess.run([sys.executable, os.path.join(ROOT, 'tools', 'options_doc.py'), '--check'],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize('option', options.OPTIONS + options.TOPIC_OPTIONS, ids=lambda o: o.name)
def test_every_default_is_valid_in_its_own_grammar(option):
    if option.default not in (None, ''):
        option.parse(option.default)
    assert option.doc and option.grammar.text and option.grammar.metavar


def test_the_configuration_file_keys_are_the_declared_ones():
    assert config.KEYS == ('topics', 'topic_limits', 'driving_topic', 'format', 'routes', 'json_xz', 'windows',
                           'limits', 'collect', 'triggers')
    with pytest.raises(ValueError) as error:
        config.Config.from_dict({'windows': {'pre': '2s', 'size': 3}})
    assert "windows: unknown key 'size' (known: pre, post, max)" in str(error.value)


def test_a_declared_default_holds_where_nothing_sets_the_option():
    cfg = config.Config.from_dict({})
    for name in ('pre', 'post', 'max_window', 'max_buffer_mb', 'format', 'max_disk_mb'):
        assert getattr(cfg, name) == options.default(name), name


def test_a_flag_comes_from_its_declaration_and_checks_its_grammar():
    parser = argparse.ArgumentParser(prog='cclog replay')
    options.add_flags(parser, 'replay')
    args = parser.parse_args(['--pre', '5m', '--max-buffer-mb', '1G'])
    assert (args.pre, args.max_buffer_mb, args.post) == ('5m', '1G', None)
    with pytest.raises(SystemExit):
        parser.parse_args(['--max-buffer-mb', 'lots'])
    cfg = config.Config.from_dict(options.with_values({}, {'pre': args.pre, 'max_buffer_mb': args.max_buffer_mb}))
    assert cfg.pre.seconds == 300 and cfg.max_buffer_mb == pytest.approx(2 ** 30 / 1e6)


def test_one_size_grammar_one_duration_grammar():
    assert spans.megabytes('1G') == spans.megabytes('1GiB') == 2 ** 30 / 1e6
    assert spans.megabytes('1GB') == 1000.0 and spans.megabytes(64) == 64.0
    assert spans.megabytes('2048', bare='b') == pytest.approx(2048 / 1e6)
    assert spans.seconds('5m') == spans.seconds('300s') == spans.seconds(300) == spans.Span.parse('5m').seconds
    assert spans.seconds('250ms') == 0.25 and spans.Span.parse('100').count == 100
    for bad in ('lots', '-1s', 'inf', float('nan'), True, [1]):
        with pytest.raises(ValueError):
            spans.seconds(bad, 'x')
    assert spans.Rotation.parse('20MB').bytes == 20 * 10 ** 6 and spans.Rotation.parse('5m').span.seconds == 300


def test_per_topic_options_are_declarations():
    limits = options.parse_topic_limits('{camera: {pre: 2s, max_mb: 1G}}')
    assert limits == {'camera': options.TopicLimits(2.0, None, 2 ** 30 / 1e6)}
    assert options.TopicLimits._fields == tuple(o.name for o in options.TOPIC_OPTIONS)


def test_every_parameter_a_node_reads_is_declared():
    """Each ``params.option('x')``/``params.value('x'...)`` in the nodes names a declared option of that node."""
    for module, node in (('smart_node', 'smart'), ('collect_node', 'collect'), ('node_extras', 'smart')):
        with open(os.path.join(ROOT, 'src', 'cc_log', 'nodes', module + '.py')) as stream:
            source = stream.read()
        names = set(re.findall(r"params\.(?:option|value|text|given)\('([a-z_]+)'", source))
        names.update(re.findall(r"given\('([a-z_]+)'\)", source))
        declared = set(o.name for o in options.for_node(node))
        assert names and names <= declared, (module, sorted(names - declared))


def test_launch_files_pass_only_declared_parameters():
    for name in ('smart.launch', 'collect.launch'):
        with open(os.path.join(ROOT, 'launch', name)) as stream:
            params = set(re.findall(r'<param\s+name="([a-z_]+)"', stream.read()))
        node = name.split('.')[0]
        assert params and params <= set(o.name for o in options.for_node(node)), (name, params)


ALL_OPTIONS = options.OPTIONS + options.TOPIC_OPTIONS


def _just_outside(within):
    """Amounts just below and just above the Range ``within`` that can be written (no negative length)."""
    if within.unit in spans.COUNTED:
        below = [within.low - 1] if within.low > 0 or within.unit == 'messages' else []
        below = [b - 1 if b == within.off else b for b in below]
        return below + [within.high + 1]
    step = lambda value: max(abs(value) * 1e-6, 1e-9)  # noqa: E731
    return [within.low - step(within.low), within.high + step(within.high)]


@pytest.mark.parametrize('option', ALL_OPTIONS, ids=lambda o: o.name)
def test_every_option_has_a_sane_range_refused_just_outside_and_accepted_at_its_bounds(option):
    """One range per option (``spans.Range``: minimum, maximum, unit; and the value that turns it off): the
    bounds (and off) are accepted, a value just outside either is refused with '<key>: <value> is outside
    <min>..<max> <unit>'. Only the grammars of a few named values (true/false, a format) have none."""
    grammar = option.grammar
    assert grammar.ranges or grammar in options.CHOICES, option.name
    name = option.key or option.name
    for within in grammar.ranges:
        assert within.low <= within.high and within.unit, (option.name, within)
        for amount in (within.low, within.high) + ((within.off,) if within.off is not None else ()):
            option.parse(within.written(amount))
        for amount in _just_outside(within):
            value = within.written(amount)
            with pytest.raises(ValueError) as error:
                option.parse(value)
            message = str(error.value)
            assert message.startswith(name + ': '), (value, message)
            assert message.endswith(' is outside %s' % str(within)), (value, message)


@pytest.mark.parametrize('option, value', [
    ('context_topics', 'odom:1e308'), ('context_rotate', '1e-300'), ('context_rotate', '1ms'), ('rotate', '1ms'),
    ('window', '1e-300s'), ('split_mb', '0.0000001'), ('split_mb', '0.5B'), ('diagnostic_period', '1e-300'),
    ('max_disk_mb', '1e-9'), ('classify_every', '1e-300s'), ('max_windows_per_hour', '1e-300'),
    ('intake_max_mb', '0'), ('max_window', '0')])
def test_the_values_accepted_that_meant_nothing_or_far_too_much_are_refused(option, value):
    """Issue 42 item 9: a rate of 1e308 Hz, a rotation per message (1e-300 s, or 1ms for 1m), a feature
    window of 1e-300 s, a sub-byte split: each refused in one line naming the option and its range."""
    with pytest.raises(ValueError) as error:
        options.get(option).parse(value)
    assert ' is outside ' in str(error.value) and '\n' not in str(error.value)


def test_a_feature_window_has_one_range_wherever_it_is_read():
    """The node's ~window, a classifier's window and a model file's config share features.WINDOW_RANGES."""
    from cc_log.features import FeatureConfig, WINDOW_RANGES
    assert options.get('window').grammar.ranges == WINDOW_RANGES
    for window in ('1e-300s', '0', '100001', '3601s'):
        with pytest.raises(ValueError) as error:
            FeatureConfig('motion', window)
        assert str(error.value).startswith("window: '%s' is outside " % window)
    assert FeatureConfig('motion', '10ms').window == '0.01s' and FeatureConfig('motion', 100000).window == '100000'

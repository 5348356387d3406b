"""Code never runs from data, and input is bounded (issue 11).

genpy turns a message definition into Python source and imports it; rosbag does so for every connection it
reads. The attack tests plant a definition that makes genpy run ``touch <marker>`` (the constant of issue
11: ``string __import__("os").system(...);X=1``) in each place a definition comes from: a json-xz window, a
bag-lz4 window, an input bag of ``cclog``, a crash leftover, a publisher on a side topic. Each one is refused
with one line naming the file or topic, and the marker never appears; ``test_the_attacks_run_in_genpy``
shows that genpy alone runs them. Then: deeply nested JSON, metadata of the wrong types, an xz bomb and
FIFOs, each answered with one line, in bounded memory and time.
"""
import ast
import hashlib
import io
import lzma
import os
import struct
import subprocess
import sys
import textwrap

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from cc_log.storage import log_format, recovery
from cc_log.base import msg_codec, safe_input
from cc_log.storage.formats import json_xz
from cc_log.storage.log_format import read_window, write_window
from cc_log.base.records import LogWindow, Record

rosbag = pytest.importorskip('rosbag')
import genpy.dynamic  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from test_cli import fails, run  # noqa: E402  (cclog as a subprocess, one-line errors)
from test_reliability import as_leftover, window  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SEP = safe_input.SEPARATOR
HEADER = SEP + 'MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n'


def payload(marker):
    """Issue 11's constant: genpy writes its name into the class body, so the name runs."""
    return 'string __import__("os").system("touch %s");X=1' % marker


def crafted_class(marker, base=Odometry):
    """``base`` whose definition carries ``payload(marker)``; an md5sum of its own, since rosbag caches the
    classes it generates by md5sum."""
    return type('Crafted', (base,), {'_full_text': payload(marker) + '\n' + base._full_text,
                                     '_md5sum': hashlib.md5(str(marker).encode()).hexdigest()})


def crafted(records, marker):
    """The records with their messages turned into ``crafted_class(marker)`` messages (same bytes)."""
    cls = crafted_class(marker, type(records[0].msg))
    out = []
    for record in records:
        buffer = io.BytesIO()
        record.msg.serialize(buffer)
        out.append(Record(record.stamp, record.topic, cls().deserialize(buffer.getvalue())))
    return out


def quick_model(directory):
    """A model file for commands that need one (trained on random vectors in a fraction of a second)."""
    import numpy as np
    from cc_log.learning import learning
    from cc_log.features import FeatureConfig, vector_length
    config = FeatureConfig('motion', '20')
    model, _ = learning.train(np.random.RandomState(0).normal(size=(60, vector_length(config))), None, config)
    return model.save(str(directory / 'model.json'))


def crafted_window(n=50, marker='/nonexistent/marker'):
    plain = window(n)
    return LogWindow(crafted(plain.records, marker), plain.triggers)


@pytest.fixture
def marker(tmp_path):
    path = tmp_path / 'marker'
    yield path
    assert not path.exists(), 'code from a message definition ran'


def one_line(error):
    text = str(error)
    assert '\n' not in text and 'Traceback' not in text
    return text


# -- the validator --------------------------------------------------------------------------------------------

def _installed_classes():
    import glob
    import importlib
    classes = []
    for init in sorted(glob.glob('/usr/lib/python3/dist-packages/*_msgs/msg/__init__.py')):
        module = importlib.import_module(init.split('/')[-3] + '.msg')
        classes += [getattr(module, name) for name in dir(module)
                    if isinstance(getattr(module, name), type) and hasattr(getattr(module, name), '_full_text')]
    return classes


def test_every_installed_message_definition_is_accepted_full_and_compact():
    classes = _installed_classes()
    assert len(classes) > 100
    for cls in classes:
        safe_input.check_definition(cls._type, cls._full_text)
        compact = msg_codec.compact_definition(cls._full_text)
        assert msg_codec.generated_class(cls._type, compact)._md5sum == cls._md5sum  # json-xz round trip


def test_every_connection_of_the_real_bags_is_accepted(real_bag):
    names = sorted(name for name in os.listdir(os.path.dirname(real_bag('husky_outdoor_2015.bag')))
                   if name.endswith('.bag'))
    for name in names:
        with rosbag.Bag(real_bag(name)) as bag:
            safe_input.check_bag(bag, name)


def test_the_attacks_run_in_genpy(tmp_path):
    """What the checks stand between: genpy alone runs a constant's name and text it rewrites."""
    for number, definition in enumerate([payload(tmp_path / 'a'), REWRITTEN % (tmp_path / 'b')]):
        sys_path = list(sys.path)
        genpy.dynamic.generate_dynamic('a/B%d' % number, 'int32 x\n' + definition + '\n')
        sys.path[:] = sys_path
    assert (tmp_path / 'a').exists() and (tmp_path / 'b').exists()


# a comment: genpy's rewrite of "import a.msg" in its source turns the quotes around it into a closing """
REWRITTEN = '# ""import a.msg"+str(__import__("os").system("touch %s"))+""import a.msg"'

ATTACKS = [  # (definition with {m} for the marker, what the refusal says)
    (payload('{m}'), 'is not an identifier'),
    ('int32 __import__("os").system("touch {m}");A=1', 'is not an identifier'),
    ('float64 A=__import__("os").system("touch {m}")', 'is not a finite number'),
    ('bool A=__import__("os").system("touch {m}")', 'is not True, False'),
    ('int32 a\'];__import__("os").system("touch {m}");b=[\'', 'is not an identifier'),
    ('int32[] __class__', 'is not an identifier'),
    ('int32 class', 'is not an identifier'),
    ('os/system(touch_{m}) x', 'is not a ROS type'),
    (REWRITTEN, 'genpy rewrites'),
    ('int32 x # class B(', 'genpy rewrites'),
    ('string A=a\\', 'would not be the same Python string'),
    ('string A=\\x41', 'would not be the same Python string'),
    ('int32 x # \\', 'would end the Python string'),
    ('int32 x # \\N', 'not a valid Python string'),
    ('int32 x\x00', 'control character'),
    ('int32 x\rimport os', 'control character'),
    ('Foo x', 'a/Foo is not defined'),
    ('Header header', 'std_msgs/Header is not defined'),
    ('int32 x\nint32 x', 'used twice'),
    ('uint8 C=256', 'is not an integer in [0, 255]'),
    ('float64 A=inf', 'is not a finite number'),
    ('float64[99999999] x', 'more than'),
    ('C c' + SEP + 'MSG: a/C\nD[] d' + SEP + 'MSG: a/D\nC c', 'contains itself'),
    ('int32 x' + SEP + 'MSG: a/B()+__import__("os")\nint32 y', 'is not package/Name'),
    ('int32 x' + SEP + 'MSG: a/C\nint32 y' + SEP + 'MSG: a/C\nint32 y', 'defined twice'),
]


@pytest.mark.parametrize('definition, reason', ATTACKS, ids=[reason for _, reason in ATTACKS])
def test_crafted_definitions_are_refused_before_genpy(definition, reason, marker):
    text = definition.replace('{m}', str(marker))
    with pytest.raises(safe_input.UnsafeDefinition) as error:
        msg_codec.generated_class('a/B', text)
    assert one_line(error.value).startswith('message definition of a/B: ') and reason in str(error.value)


def test_type_names_and_sizes_are_checked(marker):
    for msg_type in ('a/B"""\nimport os', 'os', 'a/b/c', '__import__("os")/x', ''):
        with pytest.raises(ValueError) as error:
            msg_codec.generated_class(msg_type, 'int32 x\n')
        assert 'package/Name' in one_line(error.value)
    nested = 'L0 x\n' + ''.join(SEP + 'MSG: a/L%d\nL%d x' % (i, i + 1) for i in range(40)) + SEP + 'MSG: a/L40\n'
    with pytest.raises(ValueError, match='nested deeper than 32'):
        safe_input.check_definition('a/B', nested)
    with pytest.raises(ValueError, match='longer than'):
        safe_input.check_definition('a/B', '#' * (safe_input.MAX_DEFINITION_CHARS + 1))
    with pytest.raises(ValueError, match='more than 128 message types'):  # genpy: 67 s for 1,000
        safe_input.check_definition('a/B', 'int32 x' + ''.join(SEP + 'MSG: a/C%d\n' % i for i in range(200)))
    with pytest.raises(ValueError, match='more than 10000 fields'):
        safe_input.check_definition('a/B', ''.join('int32 x%d\n' % i for i in range(10001)))


def test_a_message_with_an_empty_dependency_round_trips_compacted():
    """compact_definition keeps "MSG: pkg/Type\\n" of a type with no field, which genpy needs."""
    from nav_msgs.msg import GetMapAction
    compact = msg_codec.compact_definition(GetMapAction._full_text)
    assert msg_codec.generated_class(GetMapAction._type, compact)._md5sum == GetMapAction._md5sum


# -- any definition the validator accepts becomes a class and nothing else ----------------------------------

def genpy_source(msg_type, text):
    """The Python source genpy.dynamic.generate_dynamic would import (its own steps), not run."""
    import genmsg.msg_loader
    from genpy.dynamic import _gen_dyn_modify_references, _generate_dynamic_specs
    from genpy.generator import msg_generator
    context = genmsg.MsgContext.create_default()
    text = text.replace('roslib/Header', 'std_msgs/Header')
    parts = text.split(SEP)
    specs = {msg_type: genmsg.msg_loader.load_msg_from_string(context, parts[0], msg_type)}
    for part in parts[1:]:
        name, spec = _generate_dynamic_specs(context, specs, part)
        specs[name] = spec
    context = genmsg.MsgContext.create_default()
    for name, spec in specs.items():
        context.register(name, spec)
    return '\n'.join(_gen_dyn_modify_references(line, name, list(specs))
                     for name, spec in specs.items() for line in msg_generator(context, spec, {}))


CLASS_ATTRIBUTES = {'_md5sum', '_type', '_has_header', '_full_text', '__slots__', '_slot_types'}


def _plain_value(node):
    """A literal: a constant, a negative number, a list of strings."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        node = node.operand
    if isinstance(node, ast.List):
        return all(isinstance(item, ast.Constant) and isinstance(item.value, str) for item in node.elts)
    return isinstance(node, ast.Constant)


def check_shape(source, names):
    """Module: docstrings, imports, class definitions and struct helpers; class bodies: literal attributes
    (genpy's and the definition's constants) and methods. No call outside a function body."""
    tree = ast.parse(source)
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    continue
                assert isinstance(item, ast.Assign) and len(item.targets) == 1, ast.dump(item)
                target = item.targets[0].id
                assert target in CLASS_ATTRIBUTES or target.rstrip('_') in names, target
                assert _plain_value(item.value), ast.dump(item)
            continue
        if isinstance(node, ast.FunctionDef):
            assert node.name.startswith('_get_struct_'), node.name
            continue
        assert isinstance(node, (ast.Expr, ast.Import, ast.Assign)), ast.dump(node)
        assert not any(isinstance(sub, ast.Call) for sub in ast.walk(node)), ast.dump(node)
        if isinstance(node, ast.Import):
            assert {alias.name for alias in node.names} <= {'codecs', 'sys', 'genpy', 'struct'}


def string_constants(text):
    """{name: value} of the string constants of the first section, as genmsg reads them."""
    out = {}
    for line in text.split(SEP)[0].split('\n'):
        if '=' in line.split('#')[0] and line.split(' ')[0] == 'string':
            out[line[line.find(' ') + 1:line.find('=')].strip()] = line[line.find('=') + 1:].strip()
    return out


ATOMS = ['"', "'", '\\', '"""', "'''", '=', '#', ' ', '\t', 'a', 'B', 'x', '_', '1', '[', ']', '/', '(', ')', ';',
         '.', '+', 'import a.msg', 'class B(', 'a.msg.B', '\\n', '\\x41', '\\N{', '\r\n', '\u00e9']
text = st.lists(st.sampled_from(ATOMS), max_size=8).map(''.join)


@st.composite
def definitions(draw):
    """Mostly well-formed definitions with hostile text where text is allowed (comments, string constants),
    and now and then in names, types and values."""
    lines = []
    for number in range(draw(st.integers(1, 4))):
        name = draw(st.sampled_from(['f%d' % number] * 5 + [draw(text)]))
        kind = draw(st.sampled_from(['field'] * 2 + ['string'] * 3 + ['number', 'text'] + ['comment'] * 3))
        if kind == 'field':
            line = '%s %s' % (draw(st.sampled_from(['float64', 'string', 'bool', 'C', 'a/C[]', 'uint8[3]', 'time'])),
                              name)
        elif kind == 'string':
            line = 'string %s=%s' % (name, draw(text))
        elif kind == 'number':
            line = '%s %s=%s' % (draw(st.sampled_from(['int8', 'uint8', 'float64', 'bool', 'char'])), name,
                                 draw(st.sampled_from(['1', '-1', '0', '1.5', 'True']) | text))
        else:
            line = ('# ' if kind == 'comment' else '') + draw(text)
        if kind != 'string' and draw(st.booleans()):
            line += ' # ' + draw(text)
        lines.append(line)
    body = '\n'.join(lines)
    if draw(st.booleans()):
        body += SEP + 'MSG: a/C\nfloat64 v' + ''.join('\n# ' + draw(text) for _ in range(draw(st.integers(0, 2))))
    return body + draw(st.sampled_from(['', '\n']))


@given(definitions())
@example('string A="""\nint32 x # "')
@example('string A=a"b\'c\\d\nstring B=it\'s\nstring C=say "hi"\nstring D=\nint8 E=-128\nbool F=1\nfloat64 G=.5e3')
@example('int32 x # \\\\"\n# """"" \\""" \\\\""" a\\"')
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@pytest.mark.filterwarnings('ignore::DeprecationWarning')  # genpy keeps the '\\d' of a comment
def test_any_accepted_definition_becomes_a_class_and_nothing_else(text):
    try:
        safe_input.check_definition('a/B', text)
    except safe_input.UnsafeDefinition:
        return
    names = set(token for token in text.replace('=', ' ').split())
    check_shape(genpy_source('a/B', text), names)
    sys_path = list(sys.path)
    try:
        cls = genpy.dynamic.generate_dynamic('a/B', text)['a/B']
    finally:
        sys.path[:] = sys_path  # generate_dynamic adds a directory per call
    for name, value in string_constants(text).items():
        assert getattr(cls, name) == value


# -- window files, input bags, leftovers, publishers --------------------------------------------------------

@pytest.mark.parametrize('fmt', log_format.Format.ALL)
def test_a_crafted_window_file_is_refused_naming_file_and_topic(fmt, marker, tmp_path):
    path, _ = write_window(crafted_window(marker=marker), str(tmp_path / 'logs'), fmt)
    with pytest.raises(ValueError) as error:
        read_window(path)
    assert one_line(error.value).startswith('%s: topic /odom: message definition of nav_msgs/Odometry: ' % path)
    # info --full: info alone reads a json-xz window's metadata, not its topic sections (no definition is used)
    for args in (('info', path, '--full'), ('cat', path),
                 ('export', path, '--to', 'jsonl', '--out', tmp_path / 'x.jsonl')):
        line = fails(*args)
        assert path in line and 'topic /odom: message definition' in line and 'is not an identifier' in line


def test_a_crafted_input_bag_is_refused_by_every_command_that_reads_bags(marker, tmp_path):
    from cc_log.storage.bag import bagio
    bag_path = str(tmp_path / 'input.bag')
    with rosbag.Bag(bag_path, 'w') as bag:
        for record in crafted(window(100).records, marker):
            bag.write('/odom', record.msg, record.msg.header.stamp)
    for args in (('collect', bag_path, '--topic', '/odom', '--out', tmp_path / 'vectors'),
                 ('replay', bag_path, '--topic', '/odom', '--model', quick_model(tmp_path), '--out', tmp_path / 'l'),
                 ('codecs', bag_path, '--topic', '/odom')):
        line = fails(*args)
        assert '%s: topic /odom: message definition of nav_msgs/Odometry: ' % bag_path in line
    side = str(tmp_path / 'side.bag')  # every connection is checked, also of topics not read
    with rosbag.Bag(side, 'w') as bag:
        for record in window(30).records:
            bag.write('/odom', record.msg, record.msg.header.stamp)
        bag.write('/other', crafted(window(1).records, marker)[0].msg, record.msg.header.stamp)
    with pytest.raises(ValueError, match='topic /other: message definition'):
        list(bagio.read_messages(side, ['/odom']))


@pytest.mark.parametrize('fmt', log_format.Format.ALL)
def test_a_crafted_leftover_is_kept_unrecovered_and_never_runs(fmt, marker, tmp_path):
    directory = str(tmp_path)
    path, _ = write_window(crafted_window(3000 if fmt == 'bag-lz4' else 50, marker), directory, fmt)
    leftover = as_leftover(path)
    if fmt == 'bag-lz4':  # cut off like a SIGKILL while writing: recovery reindexes a copy and reads it
        with open(leftover, 'r+b') as stream:
            stream.truncate(os.path.getsize(leftover) * 2 // 3)
    outcome, = recovery.recover_directory(directory)
    assert outcome.status == recovery.UNRECOVERABLE and os.path.exists(leftover)
    assert 'message definition of nav_msgs/Odometry: ' in one_line(outcome.detail) and leftover in outcome.detail
    result = run('recover', directory)
    assert result.returncode == 1 and 'message definition' in result.stdout


def test_a_side_topic_publisher_with_a_crafted_definition_is_refused_counted_and_warned_once(marker, caplog):
    from cc_log.nodes.intake import MessageDecoder
    from std_msgs.msg import String

    def any_msg(msg_type, definition, data):
        """``(data, connection header)`` as the intake queues them."""
        return data, {'type': msg_type, 'message_definition': definition, 'md5sum': '*'}

    decoder = MessageDecoder({Odometry._type: Odometry})
    evil = any_msg('cc_log_test/Evil', payload(marker) + '\nfloat64 x\n', struct.pack('<d', 1.5))
    with caplog.at_level('WARNING', logger='rosout'):
        assert decoder.decode(*evil, '/side') is None and decoder.decode(*evil, '/side') is None
    assert decoder.refused == 2
    warned = [r.getMessage() for r in caplog.records if 'refused' in r.getMessage()]
    assert len(warned) == 1 and warned[0].startswith('topic /side: messages refused, never decoded: message '
                                                     'definition of cc_log_test/Evil: ')
    assert decoder.decode(*any_msg('__import__("os")/x', 'float64 x\n', b''), '/side') is None
    good = decoder.decode(*any_msg('cc_log_test/Good', 'float64 x\n', struct.pack('<d', 1.5)), '/side')
    assert good.x == 1.5 and decoder.refused == 3
    buffer = io.BytesIO()
    String(data='installed').serialize(buffer)
    assert decoder.decode(*any_msg('std_msgs/String', '', buffer.getvalue()), '/s').data == 'installed'


# -- nesting, metadata types, xz bombs, FIFOs -----------------------------------------------------------------

DEEP = '[' * 100000 + ']' * 100000


def _rewrite_json_xz(path, edit):
    with open(path, 'rb') as stream:
        text = lzma.decompress(stream.read()).decode('utf-8')
    with open(path, 'wb') as stream:
        stream.write(json_xz.compress(edit(text).encode('utf-8')))


def test_deeply_nested_json_is_refused_with_one_line(tmp_path):
    path, _ = write_window(window(5), str(tmp_path / 'logs'), 'json-xz')
    _rewrite_json_xz(path, lambda text: text.replace('{"metadata":{', '{"metadata":{"x":%s,' % DEEP, 1))
    with pytest.raises(ValueError, match='JSON nested deeper than 100 levels'):
        read_window(path)
    for args in (('info', path), ('cat', path), ('export', path, '--to', 'jsonl', '--out', tmp_path / 'x.jsonl')):
        assert path in fails(*args)
    model = tmp_path / 'model.json'
    model.write_text('{"format": "cc_log-model", "version": 1, "info": %s}' % DEEP)
    (tmp_path / 'vectors' / 'nominal').mkdir(parents=True)
    line = fails('learn', '--test', tmp_path / 'vectors', '--model', model)
    assert str(model) in line and 'nested deeper' in line
    (tmp_path / 'vectors' / 'nominal' / '1.json').write_text('{"features": %s}' % DEEP)
    assert 'nested deeper' in fails('learn', '--train', tmp_path / 'vectors', '--model', tmp_path / 'm.json')
    bag_path = str(tmp_path / 'cc_log_x.bag')  # a bag-lz4 window whose metadata nests too deep
    with rosbag.Bag(bag_path, 'w') as bag:
        record = window(1).records[0]
        bag.write('/cc_log/metadata', msg_codec.generated_class('std_msgs/String', 'string data\n')(data=DEEP),
                  record.msg.header.stamp)
        bag.write('/odom', record.msg, record.msg.header.stamp)
    with pytest.raises(ValueError, match='bad metadata JSON on /cc_log/metadata .*nested deeper'):
        read_window(bag_path)


@pytest.mark.parametrize('triggers', ['x', [1], [{'stamp': 'x'}], [{'stamp': 1.0, 'score': [1]}], {'a': 1}])
def test_metadata_of_the_wrong_type_is_refused_on_read(triggers, tmp_path):
    path, _ = write_window(window(5), str(tmp_path / 'logs'), 'json-xz', {'triggers': triggers})
    with pytest.raises(ValueError) as error:
        read_window(path)
    assert one_line(error.value) == '%s: metadata: triggers must be a list of objects {"stamp": number, ' \
                                    '"reason": string, "score": number or null, "name": string, "why": at most 3 ' \
                                    'objects of short strings (text at most 120 characters) and finite numbers}' % path
    for args in (('info', path), ('plot', path, '--out', tmp_path / 'p.png')):
        assert 'metadata: triggers must be' in fails(*args)


def test_xz_decompression_is_lzma_decompress_with_a_limit(monkeypatch):
    doc = b'{"a": 1}'
    one = lzma.compress(doc, format=lzma.FORMAT_XZ)
    cases = [one, one + one, one + b'garbage-garbage-garbage', one + b'\0' * 12, one[:-1], one[:20],
             one + one[:30], b'', one + b'garbage']
    for limit in (json_xz.ONE_PASS_BYTES, 4):  # one pass; and counted first (one pass smaller than the data)
        monkeypatch.setattr(json_xz, 'ONE_PASS_BYTES', limit)
        for data in cases:
            try:
                expected = lzma.decompress(data, format=lzma.FORMAT_XZ)
            except lzma.LZMAError:
                with pytest.raises(ValueError, match='corrupt or truncated xz data'):
                    json_xz.decompress(data, 'x', limit=100)
            else:
                assert json_xz.decompress(data, 'x', limit=100) == expected
    with pytest.raises(ValueError, match='decompresses to more than 15 bytes'):
        json_xz.decompress(one + one, 'x', limit=15)


PEAK = textwrap.dedent('''
    import resource, sys
    sys.path.insert(0, {src!r})
    from cc_log.offline import cli
    status = cli.main(['info', {path!r}])
    print(status, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
''')


def peak_of_cclog_info(path):
    """(exit status, peak RSS in MB, stderr) of ``cclog info PATH`` in a process of its own."""
    result = subprocess.run([sys.executable, '-c', PEAK.format(src=os.path.join(ROOT, 'src'), path=str(path))],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=120)
    status, peak = map(int, result.stdout.split()[-2:])
    return status, peak, result.stderr


def test_an_xz_bomb_is_refused_in_bounded_memory(tmp_path):
    bomb = tmp_path / 'cc_log_bomb.json.xz'
    bomb.write_bytes(lzma.compress(bytes(16 << 20), format=lzma.FORMAT_XZ) * 128)  # 2 GiB in 128 xz streams
    assert bomb.stat().st_size < 400000
    path, _ = write_window(window(5), str(tmp_path / 'logs'), 'json-xz')
    status, baseline, _ = peak_of_cclog_info(path)
    assert status == 0
    status, peak, stderr = peak_of_cclog_info(bomb)
    assert status == 1 and stderr == 'cclog info: error: %s: decompresses to more than %d bytes (the limit of a ' \
                                     'window document)\n' % (bomb, json_xz.MAX_DOCUMENT_BYTES)
    assert peak - baseline < json_xz.ONE_PASS_BYTES / 2 ** 20 + 30, (baseline, peak)  # 2.1 GB before the limit


def test_fifos_and_devices_are_refused_by_every_command_that_reads_a_file(tmp_path, real_bag):
    fifo = str(tmp_path / 'cc_log_fifo.json.xz')
    os.mkfifo(fifo)
    os.makedirs(str(tmp_path / 'vectors' / 'nominal'))
    os.mkfifo(str(tmp_path / 'vectors' / 'nominal' / '1.json'))
    directory = tmp_path / 'windows'
    directory.mkdir()
    os.mkfifo(str(directory / 'cc_log_20150521T191138.027Z_x.json.xz'))
    bag = real_bag('husky_outdoor_2015.bag')
    commands = [
        ('info', fifo), ('info', directory), ('cat', fifo), ('codecs', fifo),
        ('plot', fifo, '--out', tmp_path / 'p.png'),
        ('export', fifo, '--to', 'jsonl', '--out', tmp_path / 'x.jsonl'),
        ('collect', fifo, '--topic', '/odom', '--out', tmp_path / 'v'),
        ('replay', fifo, '--topic', '/odom', '--model', quick_model(tmp_path), '--out', tmp_path / 'l'),
        ('replay', bag, '--topic', '/odom', '--model', fifo, '--out', tmp_path / 'l'),
        ('learn', '--train', tmp_path / 'vectors', '--model', tmp_path / 'm.json'),
        ('learn', '--test', tmp_path / 'vectors', '--model', fifo),
    ]
    for args in commands:
        line = fails(*args)
        assert 'is a FIFO, not a regular file' in line, (args, line)
    with pytest.raises(ValueError, match='/dev/zero: is a character device, not a regular file'):
        read_window('/dev/zero')

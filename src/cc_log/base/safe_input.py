"""Input that may be hostile: message definitions, JSON nesting, files that are not files.

Nothing cc_log reads from a file or a publisher is ever run as code. genpy turns a message definition into
Python source and imports it (``genpy.dynamic.generate_dynamic``, which rosbag also calls for every
connection it reads), so a definition is checked here before any class is generated:

- ``check_definition(msg_type, text)``: the full definition (the message, then ``MSG: pkg/Type`` sections
  after lines of 80 ``=``) parsed as genmsg parses it, and accepted only when field and constant names are
  ASCII identifiers (not Python keywords), field types are ROS builtins, ``Header`` or types defined in the
  same text (short names resolved within the package, as genmsg does), constants are primitives whose value
  parses as their type, and every piece of text genpy copies into its source (string constants, the
  ``_full_text`` triple-quoted literal) stays one Python string literal with the same value. Cycles are
  refused; length, nesting, the number of types and of fields (genpy's time) and the size of a default
  instance (fixed-size arrays) are bounded.
- ``check_bag(bag, path)``: every connection and chunk header of an open rosbag, before any message is read
  (a chunk may not declare more than ``MAX_CHUNK_BYTES``, nor more than its stored bytes
  can hold: readers allocate what a chunk declares before decompressing it; a bz2 chunk must inflate to what it
  declares, counted a step at a time: rosbag inflates it whole, whatever it declares).
- ``json_loads(text)``: ``json.loads`` after a nesting check (a deeply nested document would raise
  RecursionError inside ``json``).
- ``open_input(path)``: open a file to read, refusing FIFOs, devices and sockets (a FIFO blocks forever).
- ``load_yaml(path, max_bytes)``: the one YAML reader: a bounded file, ``yaml.SafeLoader`` (no object of the
  file constructed), at most MAX_YAML_ALIASES aliases and MAX_YAML_WEIGHT nodes and scalar characters once
  aliases are expanded (an alias bomb of a few hundred bytes expands to gigabytes).
- ``brief(value)``: a repr of at most BRIEF_CHARS characters, computed in bounded time and memory: what error
  messages show of a value read from outside.

Every refusal is a ValueError with one line saying what is wrong; callers add the file or topic. Pure: no
rospy, no rosbag, no genpy.
"""
import ast
import bz2
import difflib
import functools
import json
import keyword
import os
import re
import reprlib
import stat
import sys
from cc_log.base.errors import UnsafeDefinition

__all__ = ['UnsafeDefinition', 'check_definition', 'check_connection', 'check_bag', 'check_type_name',
           'check_json_depth', 'json_loads', 'bounded_int', 'open_input', 'check_regular', 'load_yaml', 'brief',
           'MAX_DEFINITION_CHARS', 'MAX_NESTING',
           'MAX_TYPES', 'MAX_DECLARATIONS', 'MAX_DEFAULT_VALUES', 'MAX_JSON_DEPTH']

#: Longest message definition accepted (characters); real ones, comments included, are a few kB to ~50 kB.
MAX_DEFINITION_CHARS = 1 << 20
#: Deepest nesting of message types (a message is level 1); nav_msgs/Odometry reaches 4.
MAX_NESTING = 32
#: Most message types in one definition (Odometry: 6; large MoveIt messages: ~50). genpy's time grows
#: faster than the square of it: 100 types take 1.2 s, 1,000 take 67 s.
MAX_TYPES = 128
#: Most fields and constants in one definition: 10,000 take genpy 1.2 s.
MAX_DECLARATIONS = 10000
#: Most values in a default instance of a message (fixed-size arrays multiply): genpy builds one per class.
MAX_DEFAULT_VALUES = 1 << 20
#: Deepest JSON nesting accepted; a json-xz window document reaches about 2 * MAX_NESTING + 4.
MAX_JSON_DEPTH = 100
#: Most aliases (``*name``) in one YAML document.
MAX_YAML_ALIASES = 100
#: Most nodes plus scalar characters of a YAML document once its aliases are expanded (each alias counts
#: the whole of what it names): about what a file of MAX_YAML_WEIGHT bytes without aliases holds.
MAX_YAML_WEIGHT = 1 << 21
#: Longest repr of an outside value in an error message (``brief``).
BRIEF_CHARS = 80

SEPARATOR = '\n' + '=' * 80 + '\n'
_INT_RANGES = {'int8': (-2 ** 7, 2 ** 7 - 1), 'uint8': (0, 2 ** 8 - 1), 'int16': (-2 ** 15, 2 ** 15 - 1),
               'uint16': (0, 2 ** 16 - 1), 'int32': (-2 ** 31, 2 ** 31 - 1), 'uint32': (0, 2 ** 32 - 1),
               'int64': (-2 ** 63, 2 ** 63 - 1), 'uint64': (0, 2 ** 64 - 1), 'byte': (-2 ** 7, 2 ** 7 - 1),
               'char': (0, 2 ** 8 - 1)}
CONSTANT_TYPES = frozenset(_INT_RANGES) | frozenset(['float32', 'float64', 'string', 'bool'])
BUILTIN_TYPES = CONSTANT_TYPES | frozenset(['time', 'duration'])
# names genpy's generated class defines itself: a field of that name makes the class fail to build
_RESERVED = frozenset(['serialize', 'deserialize', 'serialize_numpy', 'deserialize_numpy', 'self'])

_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*\Z')
_TYPE_NAME = re.compile(r'([A-Za-z][A-Za-z0-9_]*)/([A-Za-z][A-Za-z0-9_]*)\Z')
_FIELD_TYPE = re.compile(r'([A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*)?)(?:\[([0-9]{0,9})\])?\Z')
_INT = re.compile(r'[+-]?[0-9]+\Z')
_FLOAT = re.compile(r'[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z')
_BAD_CHARACTER = re.compile(r'[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\ud800-\udfff]|\r(?!\n)')  # CRLF is fine
_STRING_STOP = re.compile(r'\\.|"""', re.S)  # CPython's tokenizer: a backslash takes the next character


# -- message definitions -----------------------------------------------------------------------------------

def check_type_name(msg_type):
    """Raise ValueError unless ``msg_type`` is ``package/Name`` (ASCII identifiers)."""
    if not isinstance(msg_type, str) or not _TYPE_NAME.fullmatch(msg_type):
        raise ValueError('message type %r is not package/Name' % (msg_type,))
    return msg_type


def check_definition(msg_type, definition):
    """Raise ValueError('message definition of <type>: <what is wrong>') unless ``definition`` (the full
    text, as ``msg._full_text`` or a connection's ``message_definition``) is safe to give genpy."""
    if not isinstance(msg_type, str) or not isinstance(definition, str):
        problem = 'the type name and the definition must be text'
    else:
        problem = _definition_problem(msg_type, definition)
    if problem:
        raise UnsafeDefinition('message definition of %s: %s' % (_shown(msg_type), problem))


def check_connection(topic, msg_type, definition, source):
    """``check_definition`` for a topic of ``source`` (a file): ValueError('<source>: topic <t>: ...')."""
    try:
        check_definition(msg_type, definition)
    except UnsafeDefinition as error:
        raise UnsafeDefinition('%s: topic %s: %s' % (source, _shown(topic), error))


def _shown(name):
    """A name from the data as it is when it is plain printable text, else quoted (one line, at most 100)."""
    text = name if isinstance(name, str) and name.isprintable() else repr(name)
    return text if len(text) <= 100 else text[:97] + '...'


def check_bag(bag, source, inflate_bz2=True):
    """Check every connection of an open ``rosbag.Bag`` before any message is read (rosbag generates a class
    from each connection's definition), and every chunk header (``check_chunks``; ``inflate_bz2``: False when
    the caller inflates chunks itself, bounded); ValueError naming ``source`` and the topic or chunk."""
    check_chunks(bag, source, inflate_bz2)
    for connection in list(getattr(bag, '_connections', {}).values()):
        check_connection(connection.topic, connection.datatype, connection.msg_def, source)


#: A decompressed chunk larger than this is not decoded (rosbag writes ~768 KiB).
MAX_CHUNK_BYTES = 1 << 28
#: Most an LZ4 block can expand (a 255:1 run-length limit), plus a frame's worth of slack.
LZ4_MAX_RATIO = 256
LZ4_SLACK = 1 << 16
#: Bytes read and inflated at a time when a bz2 chunk's size is checked (bz2 has no useful ratio bound: zeros
#: shrink ~1e5 times, so the chunk is inflated, a step at a time, and counted).
BZ2_STEP = 1 << 20


def check_chunks(bag, source, inflate_bz2=True):
    """Raise ValueError('<source>: ...') for a chunk of an open ``rosbag.Bag`` whose declared (decompressed)
    size is more than MAX_CHUNK_BYTES or more than its stored bytes can hold (uncompressed: exactly them;
    LZ4: 256 times them), or (``inflate_bz2``: for rosbag, whose ``bz2.decompress`` ignores the declared size)
    a bz2 chunk that does not inflate to its declared size (counted BZ2_STEP bytes at a time, stopped past it)."""
    stream = getattr(bag, '_file', None)
    if type(getattr(bag, '_encryptor', None)).__name__ not in ('NoneType', '_ROSBagNoEncryptor'):
        stream = None  # encrypted chunks: their bz2 is inside the ciphertext
    for pos, header in sorted(getattr(bag, '_chunk_headers', {}).items()):
        declared, stored = header.uncompressed_size, header.compressed_size
        most = {'none': stored, 'lz4': stored * LZ4_MAX_RATIO + LZ4_SLACK}.get(header.compression, MAX_CHUNK_BYTES)
        most = min(most, MAX_CHUNK_BYTES)
        if declared > most:
            raise ValueError('%s: bag is truncated or damaged (chunk at byte %d declares %d bytes, more than %d: %s, '
                             '%d bytes stored)' % (source, pos, declared, most, header.compression, stored))
        if header.compression == 'bz2' and inflate_bz2 and stream is not None:
            inflated = _bz2_inflated_size(stream, header.data_pos, stored, declared)
            if inflated != declared:
                raise ValueError('%s: bag is truncated or damaged (chunk at byte %d declares %d bytes, inflates to %s: '
                                 'bz2, %d bytes stored)' % (source, pos, declared, 'more' if inflated > declared
                                                            else '%d' % inflated, stored))


def _bz2_inflated_size(stream, start, stored, most):
    """How many bytes the ``stored`` bytes of bz2 streams at ``start`` of ``stream`` inflate to (as
    ``bz2.decompress`` reads them: stream after stream), counting stopped once past ``most``; the stream's
    position is put back. Damaged data counts as what inflated before the damage."""
    at = stream.tell()
    stream.seek(start)
    left, total = [stored], 0

    def more():
        data = stream.read(min(left[0], BZ2_STEP))
        left[0] -= len(data)
        return data
    try:
        inflater = bz2.BZ2Decompressor()
        while total <= most:
            if inflater.eof:
                data, inflater = inflater.unused_data or more(), bz2.BZ2Decompressor()
            else:
                data = more() if inflater.needs_input else b''
            if not data and inflater.needs_input:
                break
            total += len(inflater.decompress(data, BZ2_STEP))
    except (OSError, EOFError, ValueError):
        pass
    finally:
        stream.seek(at)
    return total


@functools.lru_cache(maxsize=128)
def _definition_problem(msg_type, definition):
    """What makes the definition unsafe or unusable, or None (cached: bags repeat definitions)."""
    if not _TYPE_NAME.fullmatch(msg_type):
        return 'the type name is not package/Name'
    if len(definition) > MAX_DEFINITION_CHARS:
        return 'longer than %d characters' % MAX_DEFINITION_CHARS
    bad = _BAD_CHARACTER.search(definition)
    if bad:
        return 'holds the control character %r' % bad.group()
    text = definition.replace('roslib/Header', 'std_msgs/Header')  # as genpy does first
    try:
        sections = _sections(msg_type, text)
        messages, declarations = {}, 0
        for name, body in sections:
            messages[name], count = _fields(name, body)
            declarations += count
        if declarations > MAX_DECLARATIONS:
            raise ValueError('holds more than %d fields and constants' % MAX_DECLARATIONS)
        for name, body in sections:
            _check_triple_quoted(body)
        _check_not_rewritten(text, list(messages))
        _check_references(messages)
    except ValueError as error:
        return str(error)
    return None


def _sections(msg_type, text):
    """[(type, text)]: the message itself, then each ``MSG: pkg/Type`` section (split as genpy splits)."""
    parts = text.split(SEPARATOR)
    if len(parts) > MAX_TYPES:
        raise ValueError('defines more than %d message types' % MAX_TYPES)
    sections = [(msg_type, parts[0])]
    for part in parts[1:]:
        newline = part.find('\n')
        if not part.startswith('MSG: ') or newline < 0:
            raise ValueError('a section after a line of 80 "=" does not start with "MSG: package/Name"')
        name = part[5:newline].strip()
        if not _TYPE_NAME.fullmatch(name):
            raise ValueError('section type %r is not package/Name' % name)
        sections.append((name, part[newline + 1:]))
    seen = {}
    for name, _ in sections:
        class_name = '_%s__%s' % tuple(name.split('/'))  # genpy's name for the generated class
        if class_name in seen:
            raise ValueError('%s is defined twice' % name if seen[class_name] == name
                             else '%s and %s get the same class name' % (seen[class_name], name))
        seen[class_name] = name
    return sections


def _fields(msg_type, body):
    """``(fields, declarations)`` of one section, line by line as genmsg reads it: fields are (name, resolved
    message type or None for a builtin, array length: None, -1 for ``[]`` or N); constants are checked and
    only counted in ``declarations``."""
    package = msg_type.split('/')[0]
    fields, names = [], set()
    for number, line in enumerate(body.split('\n'), 1):
        clean = line.split('#')[0].strip()
        if not clean:
            continue
        where = '%s line %d' % (msg_type, number)
        if '=' in clean:
            name = _constant(line, clean, where)
        else:
            parts = [part for part in (piece.strip() for piece in clean.split(' ')) if part]
            if len(parts) != 2:
                raise ValueError('%s: %r is not "TYPE NAME"' % (where, clean[:80]))
            field_type, name = parts
            _check_name(name, where)
            match = _FIELD_TYPE.match(field_type)
            if not match:
                raise ValueError('%s: field %s: type %r is not a ROS type' % (where, name, field_type[:80]))
            base, length = match.group(1), match.group(2)
            if base in BUILTIN_TYPES:
                target = None
            elif field_type == 'Header':  # genmsg: only the bare word, not Header[]
                target = 'std_msgs/Header'
            else:
                target = base if '/' in base else package + '/' + base
            fields.append((name, target, None if length is None else (int(length) if length else -1)))
        if name in names:
            raise ValueError('%s: the name %s is used twice' % (where, name))
        names.add(name)
    return fields, len(names)


def _check_name(name, where):
    if not _NAME.fullmatch(name) or keyword.iskeyword(name) or name in _RESERVED:
        raise ValueError('%s: name %r is not an identifier cc_log accepts (ASCII letter, then letters, digits, '
                         '_; no Python keyword)' % (where, name[:80]))


def _constant(line, clean, where):
    """Check one constant line as genmsg splits it and genpy writes it; return its name."""
    parts = [part for part in (piece.strip() for piece in clean.split(' ')) if part]
    constant_type = parts[0]
    if constant_type not in CONSTANT_TYPES:
        raise ValueError('%s: constant type %r is not a primitive type' % (where, constant_type[:80]))
    if constant_type == 'string':  # genmsg: name between the first space and '=', value all after '='
        equals = line.find('=')
        name = line[line.find(' ') + 1:equals].rstrip(' \t')
        value = line[equals + 1:].strip()
    else:
        pieces = [piece.strip() for piece in ' '.join(parts[1:]).split('=')]
        if len(pieces) != 2:
            raise ValueError('%s: %r is not "TYPE NAME=VALUE"' % (where, clean[:80]))
        name, value = pieces
    _check_name(name, where)
    what = '%s: constant %s (%s)' % (where, name, constant_type)
    if constant_type == 'string':
        try:
            same = ast.literal_eval(_genpy_string_literal(value)) == value
        except (ValueError, SyntaxError, MemoryError, RecursionError):
            same = False
        if not same:
            raise ValueError('%s: the value %r would not be the same Python string (backslash?)' % (what, value[:80]))
    elif constant_type in ('float32', 'float64'):
        if not _FLOAT.match(value) or not abs(float(value)) < float('inf'):
            raise ValueError('%s: %r is not a finite number' % (what, value[:80]))
    elif constant_type == 'bool':
        if value not in ('True', 'False') and not _INT.match(value):
            raise ValueError('%s: %r is not True, False or an integer' % (what, value[:80]))
    else:
        low, high = _INT_RANGES[constant_type]
        if not _INT.match(value) or not low <= int(value) <= high:
            raise ValueError('%s: %r is not an integer in [%d, %d]' % (what, value[:80], low, high))
    return name


def _genpy_string_literal(value):
    """The Python literal genpy 0.6 writes for a string constant (genpy.generator.msg_generator)."""
    if '"' in value and "'" in value:
        return '"%s"' % value.replace('\\', '\\\\').replace('"', '\\"')
    if '"' in value:
        return "r'%s'" % value
    if "'" in value:
        return 'r"%s"' % value
    return "'%s'" % value


def _closing_quotes(source):
    """End of the first unescaped ``\"\"\"`` in ``source`` (the inside of a triple-quoted literal), or -1."""
    for match in _STRING_STOP.finditer(source):
        if match.group() == '"""':
            return match.end()
    return -1


def _check_triple_quoted(body):
    """genpy writes the full text as ``_full_text = \"\"\"<text>\"\"\"`` after escaping ``\"\"\"``, and escapes a
    final ``"``; any section may be last. The literal must end exactly at genpy's closing quotes, in the
    middle (followed by a newline) and at the end, and be a valid Python string."""
    escaped = body.replace('"""', r'\"\"\"')
    last = escaped[:-1] + '\\"' if escaped.endswith('"') and not escaped.endswith('\\"') else escaped
    for inside in (escaped + '\n', last):
        source = inside + '"""'
        if _closing_quotes(source) != len(source):
            raise ValueError('its text would end the Python string genpy writes it into (quotes, backslashes)')
        try:
            ast.literal_eval('"""' + source)
        except (ValueError, SyntaxError, MemoryError, RecursionError):
            raise ValueError('its text is not a valid Python string once genpy quotes it (backslash escapes)')


def _check_not_rewritten(text, types):
    """genpy rewrites references in its generated source, text included: refuse text those rewrites touch."""
    patterns = ['std_msgs.msg._Header.Header']
    for name in types:
        package, base = name.split('/')
        patterns += ['import %s.msg' % package, '%s.msg.%s' % (package, base), 'class %s(' % base,
                     'super(%s,' % base]
    for pattern in patterns:
        if pattern in text:
            raise ValueError('it holds %r, which genpy rewrites in its generated source' % pattern)


def _check_references(messages):
    """Every message type used is defined; no cycle; nesting and default instance sizes bounded."""
    sizes = {}

    def size(name, path):
        if name in sizes:
            return sizes[name]
        if name in path:
            raise ValueError('%s contains itself (%s)' % (name, ' -> '.join(path + [name])))
        if len(path) >= MAX_NESTING:
            raise ValueError('message types nested deeper than %d levels' % MAX_NESTING)
        total = 1
        for field, target, length in messages[name]:
            if target is not None and target not in messages:
                raise ValueError('%s: field %s: type %s is not defined in the text' % (name, field, target))
            one = 1 if target is None else size(target, path + [name])
            total += one * length if length is not None and length >= 0 else (1 if length == -1 else one)
            if total > MAX_DEFAULT_VALUES:
                raise ValueError('%s: a default message would hold more than %d values (fixed-size arrays)'
                                 % (name, MAX_DEFAULT_VALUES))
        sizes[name] = total
        return total

    for name in messages:
        size(name, [])


# -- JSON --------------------------------------------------------------------------------------------------

_JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"', re.S)
_NOT_BRACKET = re.compile(r'[^\[\]{}]+')
_PAIR = re.compile(r'\[\]|\{\}')
_OPENERS = re.compile(r'[\[{]*')


def check_json_depth(text, limit=MAX_JSON_DEPTH):
    """Raise ValueError when the JSON ``text`` nests arrays/objects deeper than ``limit``. Cheap: regular
    expressions only (strings left out, then the innermost bracket pairs removed once per level). Brackets
    that do not match are left for ``json.loads`` to report."""
    brackets = _NOT_BRACKET.sub('', _JSON_STRING.sub('', text))
    for level in range(limit + 1):
        if not brackets:
            return
        brackets, removed = _PAIR.subn('', brackets)
        if not removed:  # not JSON: json.loads stops at the first closing bracket left, after the openers
            if level + len(_OPENERS.match(brackets).group()) <= limit:
                return
            break
    raise ValueError('JSON nested deeper than %d levels' % limit)


_MAX_INT_DIGITS = len(str(int(sys.float_info.max)))


def bounded_int(text):
    """A JSON integer (``json.loads``'s ``parse_int``) of a file whose numbers are floats (a model, an envelope),
    refused (ValueError) beyond what a float holds: none reaches numpy or ``math`` as an integer too large to
    convert (OverflowError)."""
    digits = len(text.lstrip('-'))
    value = int(text) if digits <= _MAX_INT_DIGITS else None
    if value is None or abs(value) > sys.float_info.max:
        raise ValueError('an integer of %d digits is out of range' % digits)
    return value


def json_loads(text, **kwargs):
    """``json.loads(text, **kwargs)`` of str or UTF-8 bytes, after ``check_json_depth``; ValueError for
    anything that is not JSON."""
    if isinstance(text, (bytes, bytearray)):
        text = bytes(text).decode('utf-8')
    check_json_depth(text)
    try:
        return json.loads(text, **kwargs)
    except RecursionError:  # not expected after the depth check; never a traceback
        raise ValueError('JSON nested too deeply')


# -- files -------------------------------------------------------------------------------------------------

_KINDS = ((stat.S_ISDIR, 'a directory'), (stat.S_ISFIFO, 'a FIFO'), (stat.S_ISSOCK, 'a socket'),
          (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'))


def check_regular(path, mode):
    """Raise ValueError('<path>: is a FIFO, not a regular file') unless ``mode`` (st_mode) is a regular file."""
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _KINDS if test(mode)), 'not a regular file')
        raise ValueError('%s: is %s, not a regular file' % (path, kind))


def open_input(path):
    """Open ``path`` for reading (binary); ValueError for anything but a regular file, without blocking on a
    FIFO (opened non-blocking, checked on the descriptor). OSError when it cannot be opened."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_NOCTTY', 0))
    try:
        check_regular(path, os.fstat(fd).st_mode)
        os.set_blocking(fd, True)
        return os.fdopen(fd, 'rb')
    except BaseException:
        os.close(fd)
        raise


# -- YAML and error messages -------------------------------------------------------------------------------

def _yaml_weight(node, memo, open_nodes):
    """Nodes plus scalar characters under ``node``, aliases expanded (``memo``: by id); ValueError for a
    node that contains itself."""
    key = id(node)
    if key in memo:
        return memo[key]
    if key in open_nodes:
        raise ValueError('a YAML alias refers to a node that contains it')
    if isinstance(node.value, str):
        weight = 1 + len(node.value)
    else:
        open_nodes.add(key)
        items = [part for pair in node.value for part in pair] if node.id == 'mapping' else node.value
        weight = 1 + sum(_yaml_weight(item, memo, open_nodes) for item in items)
        open_nodes.discard(key)
    memo[key] = weight
    return weight


def _safe_loader(text):
    """A ``yaml.SafeLoader`` of ``text`` that counts aliases and checks the expanded weight of the document."""
    import yaml

    class BoundedLoader(yaml.SafeLoader):
        aliases = 0

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                self.aliases += 1
                if self.aliases > MAX_YAML_ALIASES:
                    raise ValueError('more than %d YAML aliases' % MAX_YAML_ALIASES)
            return super(BoundedLoader, self).compose_node(parent, index)

        def get_single_node(self):
            node = super(BoundedLoader, self).get_single_node()
            if node is not None and _yaml_weight(node, {}, set()) > MAX_YAML_WEIGHT:
                raise ValueError('YAML aliases expand to more than %d nodes and characters' % MAX_YAML_WEIGHT)
            return node

    return BoundedLoader(text)


def load_yaml(path, max_bytes):
    """The document of the YAML file ``path`` (at most ``max_bytes``; see the module docstring);
    ValueError('<path>: ...') with one line when it cannot be read, is too large or is not YAML."""
    try:
        with open_input(path) as stream:
            data = stream.read(max_bytes + 1)
    except (IOError, OSError) as error:
        raise ValueError('%s: cannot read: %s' % (path, error.strerror or error))
    if len(data) > max_bytes:
        raise ValueError('%s: larger than %d bytes' % (path, max_bytes))
    try:
        text = data.decode('utf-8')
    except ValueError as error:
        raise ValueError('%s: not YAML: %s' % (path, ' '.join(str(error).split())[:200]))
    return loads_yaml(text, path)


def loads_yaml(text, name):
    """The document of YAML ``text`` (a parameter's, a file's: bounded as ``load_yaml``'s); ValueError('<name>:
    not YAML: ...') with one line."""
    import yaml
    try:
        loader = _safe_loader(text)
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    except (ValueError, yaml.YAMLError, RecursionError) as error:
        raise ValueError('%s: not YAML: %s' % (name, ' '.join(str(error).split())[:200]))


_BRIEF = reprlib.Repr()
_BRIEF.maxlevel = 3
_BRIEF.maxstring = _BRIEF.maxother = _BRIEF.maxlong = BRIEF_CHARS
for _name in ('maxtuple', 'maxlist', 'maxarray', 'maxdict', 'maxset', 'maxfrozenset', 'maxdeque'):
    setattr(_BRIEF, _name, 8)


def brief(value, limit=BRIEF_CHARS):
    """A repr of ``value`` of at most ``limit`` characters (``...`` where cut), whatever its size."""
    text = _BRIEF.repr(value)
    return text if len(text) <= limit else text[:limit - 3] + '...'


def closest(name, known):
    """The name of ``known`` nearest to ``name`` (``difflib.get_close_matches``), None when none is near."""
    if not isinstance(name, str):
        return None
    near = difflib.get_close_matches(name, [k for k in known if isinstance(k, str)], n=1)
    return near[0] if near else None


def unknown_key(data, known, where=''):
    """'' when every key of the mapping ``data`` is ``known``, else the error text for the first unknown one:
    ``<where>: unknown key 'formt' (did you mean 'format'? known: ...)``."""
    unknown = sorted((key for key in data if key not in known), key=brief)
    if not unknown:
        return ''
    near = closest(unknown[0], known)
    return '%sunknown key %s (%sknown: %s)' % (where + ': ' if where else '', brief(unknown[0]),
                                               'did you mean %s? ' % brief(near) if near else '', ', '.join(known))


# control characters (a terminal escape sequence starts with one) and the bidirectional overrides
_UNPRINTABLE = re.compile('[\x00-\x1f\x7f-\x9f\u200e\u200f\u202a-\u202e\u2066-\u2069]')


def printable(text):
    """``text`` with control characters shown as ``\\xNN`` / ``\\uNNNN``: names read from files or the network
    (topics, reasons, paths) never reach a terminal as escape sequences."""
    return _UNPRINTABLE.sub(lambda found: ascii(found.group())[1:-1], str(text))

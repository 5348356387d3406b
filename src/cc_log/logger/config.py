"""One configuration, live and offline: topics, triggers (models, rules), windows, format and limits.

The same YAML file drives ``smart_logger.py`` and ``collect_logger.py`` (``~config``, or loaded into their
private namespace with ``rosparam load``), ``cclog replay --config`` and ``cclog collect --config``, so a
configuration tuned offline on bags behaves the same on the robot::

    topics: [imu/data, scan]          # other topics to keep in the windows; also '*', 're:/camera/.*', '!/tf'
    driving_topic: odom               # counts pre and post (default: the first trigger's first topic)
    format: json-xz
    json_xz: {precision: {'pose.pose.position.*': 1e-4, 'twist.twist.*': 1e-5}}   # lossy, opt-in
    windows: {pre: 2s, post: 2s, max: 100000}
    limits: {max_disk_mb: 500, min_free_mb: 100, max_buffer_mb: 256}
    collect: {rotate: 60s, label: nominal, stride: 25}
    triggers:
      - {name: motion, kind: classifier, model: ~/.ros/cc_log/motion.json, topics: [odom],
         classify_every: 50ms, retrigger: event, recent: 0.5s, learn_online: false}   # learn_*: cc_log.online_learning
      - {name: shock, kind: classifier, model: ~/.ros/cc_log/imu.json, topics: [imu/data]}
      - {name: motors, kind: rule, topic: /diagnostics, level: ERROR, status: 'motor*', hold_off: 5s}
      - {name: too_fast, kind: rule, topic: odom, type: nav_msgs/Odometry, when: 'twist.twist.linear.x > 2.0'}
      - {name: bumper, kind: rule, topic: bumper, arrival: true, keep: [scan, 're:/camera/.*']}  # only these
      - {name: scan_dead, kind: rule, topic: scan, silent: 1s}

A trigger's ``keep`` (names and patterns as ``topics``; its names are subscribed, or read from a bag, like
those of ``topics``): a window only such triggers opened holds the driving topic and these, no other.
``Config.from_dict`` checks everything at start: an unknown key, trigger kind, feature set, field or message
type fails with one line naming it (``ValueError('<source>: triggers[2] (motors): level: ...')``). Topic
names may be relative: nodes resolve them in their namespace, offline tools as global names (``odom`` is
``/odom`` in a bag). A classifier's ``feature_set`` and ``window`` are what collect mode computes (default:
its model's when the model file can be read, else ``motion`` and ``500``); in smart mode they must match the
model. Pure: yaml, no rospy.
"""
import copy
import os

from cc_log import features
from cc_log.storage import log_format
from cc_log.base import safe_input
from cc_log.base.safe_input import brief
from cc_log.learning.model import check_window
from cc_log.logger import options
from cc_log.base.spans import Span
from cc_log.triggers import get as trigger_kind
from cc_log.triggers.base import Context, check_name
from cc_log.triggers.classifier import default_topics
from cc_log.base.topic_select import TopicSelection, topic_list

KEYS = tuple(options.sections())
COMMON_TRIGGER_KEYS = ('name', 'kind', 'pre', 'post', 'keep')
DEFAULT_FEATURE_SET = options.get('feature_set').default
DEFAULT_WINDOW = options.get('window').default
MAX_FILE_BYTES = 1 << 20


def load_file(path):
    """The configuration dict of a YAML file; ValueError('<path>: ...') when it cannot be read or is not
    a mapping (read by ``safe_input.load_yaml``: ``safe_load``'s loader, no object of the file is ever
    constructed or run; size and aliases bounded)."""
    document = safe_input.load_yaml(path, MAX_FILE_BYTES)
    if document is None:
        return {}
    if not isinstance(document, dict):
        raise ValueError('%s: a configuration is a mapping of %s, not %s' % (
            path, ', '.join(KEYS), type(document).__name__))
    return document


def merge(base, override):
    """``base`` with ``override``'s keys: mappings (windows, limits, collect) merged key by key, anything
    else (topics, triggers) replaced. Neither argument is changed."""
    result = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(result.get(key), dict):
            result[key] = merge(result[key], value)
        else:
            result[key] = copy.deepcopy(value)
    return result


def with_flat(data, flat):
    """``data`` with the options of ``flat`` (``{'pre': '2s', ...}``: names of ``options.OPTIONS`` with a
    configuration key; None values are ignored) at their keys."""
    return merge(data, options.with_values({}, flat))


def model_kind(path):
    """The default trigger the file ``path`` builds where a model is given (``~model``, ``cclog replay
    --model``): ``'envelope'`` for an envelope file (its JSON ``kind`` is ``cc_log envelope``: ``cclog
    learn-envelope``), ``'classifier'`` for a cc_log model (``cclog learn``), and for a file that cannot be read
    or is too large for an envelope (the model's reader says what is wrong); ValueError('<path>: ...') for any
    other file."""
    from cc_log.learning import envelope, model
    try:
        with safe_input.open_input(os.path.expanduser(path)) as stream:
            text = stream.read(envelope.MAX_FILE_BYTES + 1)
    except (OSError, ValueError):
        return 'classifier'
    if len(text) > envelope.MAX_FILE_BYTES:
        return 'classifier'
    try:
        document = safe_input.json_loads(text, parse_int=safe_input.bounded_int)
    except ValueError:
        document = None
    if isinstance(document, dict) and document.get('kind') == envelope.KIND:
        return 'envelope'
    if isinstance(document, dict) and document.get('format') == model.FORMAT:
        return 'classifier'
    raise ValueError('%s: not a cc_log model nor an envelope file (cclog learn or cclog learn-envelope writes '
                     'one)' % path)


def with_classifier(data, **values):
    """``data`` with the single-classifier parameters of the nodes and ``cclog`` (None: not given):
    ``model``, ``topics``, ``feature_set`` and ``window`` go to the trigger named ``classifier`` (added first
    when there is none; without ``topics``, on its feature set's default topics); ``classify_every``,
    ``retrigger``, ``recent`` and ``learn_online`` to every classifier, ``on_drift`` to every envelope trigger.
    When ``model`` is an envelope file (``model_kind``), it goes to the trigger named ``envelope`` instead (of
    kind envelope, added first when there is none; ``topics``: its one odometry topic, default the file's).
    ValueError naming what is wrong."""
    data = copy.deepcopy(data)
    triggers = data.get('triggers', [])
    if not isinstance(triggers, list):
        return data  # from_dict says what is wrong
    own = dict((key, values[key]) for key in ('model', 'topics', 'feature_set', 'window')
               if values.get(key) is not None)
    if 'model' in own and isinstance(own['model'], str) and model_kind(own['model']) == 'envelope':
        _default_trigger(triggers, 'envelope', _envelope_entry(own))
        own = {}
    if own:
        _default_trigger(triggers, 'classifier', own)
    for key, kind in (('classify_every', 'classifier'), ('retrigger', 'classifier'), ('recent', 'classifier'),
                      ('learn_online', 'classifier'), ('on_drift', 'envelope')):
        if values.get(key) is not None:
            for entry in triggers:
                if isinstance(entry, dict) and entry.get('kind') == kind:
                    entry[key] = values[key]
    if triggers:
        data['triggers'] = triggers
    return data


def _envelope_entry(own):
    """The options of the default envelope trigger from the single-classifier parameters ``own``."""
    for key in ('feature_set', 'window'):
        if key in own:
            raise ValueError('%s: %s is an envelope file (cclog learn-envelope): its features and window are its '
                             'own, not a classifier\'s' % (key, own['model']))
    entry = {'limits': own['model']}
    if 'topics' in own:
        topics = topic_list(own['topics'], 'topics')
        if len(topics) != 1:
            raise ValueError('topics: the envelope of %s reads one odometry topic, not %d'
                             % (own['model'], len(topics)))
        entry['topic'] = topics[0]
    return entry


def _default_trigger(triggers, kind, options):
    """Update the trigger named ``kind`` of that kind in ``triggers`` with ``options`` (added first when none)."""
    named = [entry for entry in triggers if isinstance(entry, dict)
             and entry.get('kind') == kind and entry.get('name', kind) == kind]
    if not named:
        named = [{'name': kind, 'kind': kind}]
        triggers.insert(0, named[0])
    named[0].update(options)


def global_name(topic):
    """How offline tools resolve a topic name: relative names are global (``odom`` -> ``/odom``)."""
    return topic if topic.startswith('/') else '/' + topic


class Config(object):
    """A checked configuration (see the module docstring); build it with ``from_dict``.

    Attributes: topics, driving_topic (None: the first trigger's first topic), format, precision (json-xz
    rounding, ``{}``: lossless), pre, post,
    max_window (Spans), max_disk_mb, min_free_mb, max_files, max_buffer_mb, split_mb, max_windows_per_hour (the keep
    budget), rotate, label, stride (None: the collector's defaults), triggers (checked trigger entries, dicts with
    ``name`` and ``kind``), source.
    """

    def __init__(self):
        self.source = 'config'

    @classmethod
    def from_dict(cls, data, source='config'):
        """Check ``data`` (a dict of KEYS); ValueError('<source>: <key>: ...') for anything wrong."""
        self = cls()
        self.source = source
        try:
            self._read(data if data is not None else {})
        except ValueError as error:
            raise ValueError('%s: %s' % (source, error))
        return self

    def _read(self, data):
        values = options.read(data)
        entries = values['topics'] or []
        self.selection = TopicSelection.parse(entries, 'topics')  # names and patterns (*, re:..., !...)
        self.topics = [entry for entry in entries if not TopicSelection.is_pattern(entry)]
        for name in ('topic_limits', 'format', 'routes', 'precision', 'pre', 'post', 'max_window', 'max_disk_mb',
                     'min_free_mb', 'max_buffer_mb', 'split_mb', 'max_files', 'max_windows_per_hour'):
            setattr(self, name, values[name] if values[name] is not None else options.default(name))
        self.driving_topic = values['driving_topic']
        if self.precision and log_format.Format.JSON_XZ not in [self.format] + [r.format for r in self.routes]:
            raise ValueError('json_xz.precision: rounds json-xz windows only (format is %s)' % self.format)
        self.rotate = None if values['rotate'] is None else str(values['rotate'])
        self.label, self.stride = values['label'], values['stride']  # None: the collector's defaults
        triggers = data.get('triggers', [])
        if not isinstance(triggers, list):
            raise ValueError('triggers: a list of triggers, not %s' % brief(triggers))
        self.triggers = []
        names = set()
        for index, entry in enumerate(triggers):
            checked = _trigger_entry(entry, index)
            if checked['name'] in names:
                raise ValueError('triggers[%d]: name %s is used twice' % (index, brief(checked['name'])))
            names.add(checked['name'])
            self.triggers.append(checked)
        if values['pre'] is None:  # not given: the default, or the longest pre a trigger asks for
            self.pre = max([self.pre] + [_pre_of(entry) for entry in self.triggers if _pre_of(entry)],
                           key=lambda span: (span.is_duration == self.pre.is_duration, span.seconds or span.count))
        for index, entry in enumerate(self.triggers):
            _check_pre(entry, index, self.pre)

    # -- what the modes build from it -----------------------------------------------------------------

    def _where(self, entry):
        return '%s: triggers[%d] (%s)' % (self.source, entry['index'], entry['name'])

    def build_triggers(self, load_model, message_class, resolve=global_name, online_dir=None):
        """The Trigger objects of smart mode. ``load_model(path)``: a model (raising ValueError naming the
        file); ``message_class(type)``: the class of a message type, or None when it is not installed;
        ``resolve(topic)``: a topic's full name; ``online_dir``: where online learning keeps its refits (None:
        beside the model files). ValueError naming the trigger for anything wrong."""
        context = Context(load_model, message_class, resolve, online_dir)
        built = []
        for entry in self.triggers:
            options = dict((key, value) for key, value in entry.items() if key not in ('name', 'kind', 'index', 'keep'))
            try:
                built.append(trigger_kind(entry['kind']).from_config(entry['name'], options, context))
            except ValueError as error:
                text = str(error)
                prefix = entry['name'] + ': '
                raise ValueError('%s: %s' % (self._where(entry), text[len(prefix):] if text.startswith(prefix)
                                             else text))
        return built

    def feature_specs(self, load_model=None, resolve=global_name):
        """What collect mode computes: ``[(name, FeatureConfig, topics)]`` of every classifier entry (its
        ``feature_set`` and ``window``, else its model's when ``load_model`` can read it, else the defaults)."""
        specs = []
        for entry in self.triggers:
            if entry['kind'] != 'classifier':
                continue
            where = self._where(entry)
            model_config = None
            if load_model is not None and isinstance(entry.get('model'), str):
                try:
                    model_config = load_model(os.path.expanduser(entry['model'])).config
                except ValueError:
                    model_config = None  # collect mode comes before the model exists
            feature_set = entry.get('feature_set', model_config.feature_set if model_config else DEFAULT_FEATURE_SET)
            window = entry.get('window', model_config.window if model_config else DEFAULT_WINDOW)
            try:
                config = features.FeatureConfig(feature_set, str(window))
                check_window(config)
            except ValueError as error:
                raise ValueError('%s: %s' % (where, error))
            try:
                topics = default_topics(entry.get('topics'), feature_set, resolve)
            except ValueError as error:
                raise ValueError('%s: %s' % (where, error))
            specs.append((entry['name'], config, topics))
        return specs

    def logger_options(self, triggers, resolve=global_name):
        """Keyword arguments of SmartLogger for ``triggers`` (built by ``build_triggers``)."""
        driving = self.driving_topic
        if driving is None:
            first = [t for t in triggers if t.topics]
            if not first:
                raise ValueError('%s: driving_topic: needed when no trigger watches a topic' % self.source)
            driving = first[0].topic if hasattr(first[0], 'topic') else sorted(first[0].topics)[0]
        return {'fmt': self.format, 'pre': self.pre, 'post': self.post, 'max_window': self.max_window,
                'driving_topic': resolve(driving),
                'side_topics': None if self.selection.dynamic else
                [resolve(t) for t in self.named_topics()],
                'max_disk_mb': self.max_disk_mb, 'min_free_mb': self.min_free_mb, 'max_files': self.max_files,
                'max_buffer_mb': self.max_buffer_mb, 'split_mb': self.split_mb, 'triggers': triggers,
                'max_windows_per_hour': self.max_windows_per_hour,
                'format_options': self.format_options(),
                'topic_limits': dict((resolve(topic), limits) for topic, limits in self.topic_limits.items()),
                'routes': [route.resolved(resolve) for route in self.routes],
                'keep': dict((entry['name'], entry['keep'].resolved(resolve))
                             for entry in self.triggers if 'keep' in entry)}

    def keep_names(self):
        """The topic names (not patterns) the triggers' ``keep`` lists name: subscribed, or read from a bag,
        like the names of ``topics`` (a window cannot keep a topic nobody listens to)."""
        return list(dict.fromkeys(name for entry in self.triggers if 'keep' in entry for name in entry['keep'].names))

    def route_names(self):
        """The topic names (not patterns) only the routes name: a bag may lack them (a route is where a topic
        goes when it comes, not a topic a window needs)."""
        named = set(self.topics + self.keep_names())
        return [name for name in dict.fromkeys(name for route in self.routes for name in route.selection.names)
                if name not in named]

    def named_topics(self):
        """The topic names (not patterns) of ``topics``, the triggers' ``keep`` lists and the routes, in that
        order: the names subscribed (or read from a bag: it must hold them) besides what patterns select, and
        those a node warns of when nothing comes on them."""
        return list(dict.fromkeys(self.topics + self.keep_names() + [
            name for route in self.routes for name in route.selection.names]))

    def format_options(self):
        """What the window format is told in each window's metadata: ``{'precision': ...}`` when set."""
        return {'precision': self.precision} if self.precision else {}


def _pre_of(entry):
    """A trigger's own ``pre`` (a Span), or None."""
    pre = entry.get('pre')
    return None if pre in (None, '') else Span.parse(pre, 'triggers[%d] (%s): pre' % (entry['index'], entry['name']))


def _check_pre(entry, index, held):
    """A trigger's own ``pre`` may not be longer than ``windows.pre`` (``held``): the logger holds no more."""
    span = _pre_of(entry)
    if span is None:
        return
    where = 'triggers[%d] (%s): pre' % (index, entry['name'])
    if span.is_duration == held.is_duration and (span.seconds or span.count) > (held.seconds or held.count):
        raise ValueError('%s: %s is longer than windows.pre %s, the most the logger holds before a trigger: raise '
                         'windows.pre (and give shorter triggers their own pre)' % (where, span, held))


def _trigger_entry(entry, index):
    """A trigger entry checked for its keys: a dict with name, kind and index."""
    if not isinstance(entry, dict):
        raise ValueError('triggers[%d]: a mapping with name and kind, not %s' % (index, brief(entry)))
    kind = entry.get('kind')
    try:
        trigger_kind(kind)
    except ValueError as error:
        raise ValueError('triggers[%d] (%s): %s' % (index, entry.get('name', '?'), error))
    name = entry.get('name', kind)
    try:
        check_name(name)
    except ValueError as error:
        raise ValueError('triggers[%d]: %s' % (index, error))
    options.known_keys(entry, COMMON_TRIGGER_KEYS + trigger_kind(kind).config_keys, 'triggers[%d] (%s)' % (index, name))
    if kind == 'classifier' and 'feature_set' in entry:
        try:
            features.get(entry['feature_set'])
        except ValueError as error:
            raise ValueError('triggers[%d] (%s): %s' % (index, name, error))
    checked = dict(entry)
    checked.update(name=name, kind=kind, index=index)
    if 'keep' in entry:  # the topics a window opened only by such triggers keeps, besides the driving topic
        where = 'triggers[%d] (%s): keep' % (index, name)  # names and patterns, as ``topics``
        checked['keep'] = TopicSelection.parse(topic_list(entry['keep'], where), where)
    return checked

"""One place resolves message classes (issue 44): ``raw_message.message_class`` picks the installed class or the
one genpy generates from a definition (``msg_codec.generated_class``); ``installed_class`` is its answer without
a definition (a configuration's types)."""
import os
import re

import pytest

from cc_log.base import msg_codec, raw_message

SRC = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'src', 'cc_log')


def calls(pattern):
    """The modules below src/cc_log (relative paths) whose code matches ``pattern``."""
    found = []
    for folder, _, names in os.walk(SRC):
        for name in names:
            if name.endswith('.py'):
                path = os.path.join(folder, name)
                with open(path) as stream:
                    if re.search(pattern, stream.read()):
                        found.append(os.path.relpath(path, SRC))
    return sorted(found)


def test_only_raw_message_asks_roslib_and_only_msg_codec_asks_genpy_for_a_class():
    assert calls(r'get_message_class\(') == ['base/raw_message.py']
    assert calls(r'generate_dynamic\(') == ['base/msg_codec.py']
    assert calls(r'\bgenerated_class\(') == sorted(['base/msg_codec.py', 'base/raw_message.py',
                                                    'storage/formats/json_xz.py'])


def test_installed_class_is_the_resolver_without_a_definition():
    from nav_msgs.msg import Odometry
    assert raw_message.installed_class('nav_msgs/Odometry') is Odometry
    assert raw_message.installed_class('no_such_package/Thing') is None
    with pytest.raises(ValueError, match='type'):
        raw_message.installed_class('../evil')


def test_a_definition_is_generated_only_when_the_installed_class_does_not_fit():
    from std_msgs.msg import String
    text = 'string data\n'
    assert raw_message.message_class({'type': 'std_msgs/String', 'md5sum': String._md5sum,
                                      'message_definition': text}) is String
    other = raw_message.message_class({'type': 'std_msgs/String', 'md5sum': 'f' * 32,
                                       'message_definition': 'int32 data\n'})
    assert other is msg_codec.generated_class('std_msgs/String', 'int32 data\n') and other is not String
    custom = raw_message.message_class({'type': 'cc_log_test/Custom', 'md5sum': '*', 'message_definition': text})
    assert custom is msg_codec.generated_class('cc_log_test/Custom', text)

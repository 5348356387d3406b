#!/usr/bin/python3
"""Test node of reliability_disk.test: the live smart node on a 2 MB tmpfs mounted by this test (root).

1. ~max_disk_mb: windows keep coming; the oldest cc_log window files are deleted so the newest fit the quota;
   /diagnostics says how many were deleted; a file that is not a cc_log window is never touched.
2. ~min_free_mb: the disk is filled below the floor; writing stops, /diagnostics is ERROR ("disk nearly
   full"), windows wait in memory; space returns (the filler is removed): they are written, nothing lost.
3. ENOSPC during a write (no floor, the disk filled to the last byte): the node reports ERROR, keeps the
   windows in memory and keeps running; space returns: they are written, nothing lost.
4. The disk full to the last byte and old windows over ~max_disk_mb: the quota makes room, oldest written
   first, so windows are written while it stays full, and none is lost at shutdown.
5. The collect node on a full disk: files and feature vectors are held and retried (ERROR on /diagnostics),
   no empty ``*.tmp-*`` file is left, a crash leftover planted before the start is recovered and counted;
   space returns: every message is in a file.

Skipped, with the reason printed, when a tmpfs cannot be mounted (not root, no mount permission).
"""
import errno
import os
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402
from reliability_crash_check import Streamer, make_model  # noqa: E402

from cc_log.storage import log_format, recovery  # noqa: E402
from test_reliability import window  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger_disk'
SIZE = '2m'
MOUNT_ERROR = None


def mount_tmpfs(path):
    """Mount a SIZE tmpfs at ``path``; None, or why it cannot be done."""
    if os.geteuid() != 0:
        return 'not root (a tmpfs mount needs root)'
    try:
        result = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=%s,mode=2775' % SIZE, 'tmpfs', path],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True,
                                timeout=20)
    except (OSError, subprocess.TimeoutExpired) as error:
        return 'mount failed: %s' % error
    if result.returncode:
        return 'mount -t tmpfs failed: %s' % (result.stderr.strip() or result.returncode)
    return None


def fill(path, leave_bytes):
    """A filler file that leaves about ``leave_bytes`` free (0: fill to ENOSPC)."""
    status = os.statvfs(os.path.dirname(path))
    free = status.f_bavail * status.f_frsize
    size = max(0, free - leave_bytes)
    with open(path, 'ab') as stream:
        block = b'\0' * 65536
        written = 0
        try:
            while written < size or not leave_bytes:
                stream.write(block[:max(1, min(len(block), size - written))] if leave_bytes else block)
                stream.flush()
                written += len(block)
        except OSError as error:
            if error.errno != errno.ENOSPC:
                raise


class DiskTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('reliability_disk_check')
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_disk_')
        cls.disk = os.path.join(cls.tmp, 'disk')
        os.makedirs(cls.disk)
        cls.mount_error = mount_tmpfs(cls.disk)
        if cls.mount_error:
            sys.stdout.write('SKIPPED reliability_disk: %s\n' % cls.mount_error)
            sys.stderr.write('SKIPPED reliability_disk: %s\n' % cls.mount_error)
        cls.model = make_model(os.path.join(cls.tmp, 'model.json'), always=True)
        cls.diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.stream = Streamer('disk_odom', 'disk_imu')
        cls.node = None

    @classmethod
    def tearDownClass(cls):
        if not cls.mount_error:
            subprocess.call(['umount', '-l', cls.disk])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def setUp(self):
        if self.mount_error:
            self.skipTest(self.mount_error)

    def tearDown(self):
        if self.node is not None:
            code, out, err = fx.stop(self.node)
            self.output = out + err
            type(self).node = None

    def start(self, directory, *params):
        del self.diagnostics[:]
        type(self).node = fx.start('smart_logger.py', '__name:=' + NODE, 'odom:=disk_odom', '_topics:=disk_imu',
                                   '_model:=' + self.model, '_directory:=' + directory, '_pre:=10', '_post:=10',
                                   '_max_window:=300', '_diagnostic_period:=0.2', '_format:=json-xz',
                                   '_max_disk_mb:=0', '_min_free_mb:=0', *params)  # private params persist
        fx.wait_for(lambda: fx.status_values(self.diagnostics, NODE)[0] is not None, 30, 'the smart node to start')
        fx.wait_for(lambda: self.stream.connected() and fx.subscribed('/disk_imu', '/' + NODE), 30,
                    'the smart node to subscribe')
        time.sleep(0.5)

    def status(self):
        return fx.status_values(self.diagnostics, NODE)

    def wait_status(self, predicate, what, timeout=15):
        fx.wait_for(lambda: predicate(*self.status()), timeout, what)
        return self.status()

    def test_1_quota_keeps_the_newest_windows(self):
        directory = os.path.join(self.disk, 'quota')
        os.makedirs(directory)
        other = os.path.join(directory, 'notes.txt')
        with open(other, 'wb') as stream:
            stream.write(b'n' * 50000)
        quota = 0.25  # MB
        self.start(directory, '_format:=bag-lz4', '_max_disk_mb:=%gkB' % (quota * 1000))  # a size with a unit
        sent = self.stream.publish(3.0, 1000.0)
        # every message taken in (else a window cut later makes the quota delete a file listed below)
        level, message, values = self.wait_status(
            lambda level, message, values: values.get('messages seen') == str(2 * sent)
            and values.get('intake queue') == '0' and values.get('writer queue') == '0'
            and int(values.get('windows deleted (quota)', 0)) > 0, 'windows deleted by the quota', 30)
        files = log_format.window_files(directory)
        sizes = [os.path.getsize(path) for path in files]
        self.assertLessEqual(sum(sizes), quota * 1e6 + max(sizes))  # at most the newest window over
        saved, deleted = int(values['windows saved']), int(values['windows deleted (quota)'])
        self.assertEqual(len(files), saved - deleted)
        self.assertIn('deleted to stay within ~max_disk_mb', message)
        self.assertEqual(values['last deleted'] < files[0], True)  # the oldest went
        self.assertTrue(os.path.exists(other))
        for path in files:
            log_format.read_window(path)

    def test_2_min_free_pauses_and_resumes(self):
        directory = os.path.join(self.disk, 'floor')
        os.makedirs(directory)
        filler = os.path.join(self.disk, 'filler_floor')
        self.start(directory, '_min_free_mb:=600kB')
        fill(filler, 300000)  # 0.3 MB left, under the 0.6 MB floor
        self.stream.publish(1.5, 500.0)
        level, message, values = self.wait_status(
            lambda level, message, values: int(values.get('windows held', 0)) >= 2, 'windows held in memory')
        self.assertEqual(level, DiagnosticStatus.ERROR)
        self.assertIn('disk nearly full', message)
        self.assertEqual(values['writing paused'], 'True')
        self.assertEqual(log_format.window_files(directory), [])
        os.unlink(filler)  # space returns
        level, message, values = self.wait_status(
            lambda level, message, values: values.get('windows held') == '0' and values.get('writer queue') == '0'
            and values.get('intake queue') == '0' and len(log_format.window_files(directory)) == int(
                values.get('windows saved', -1)), 'the held windows to be written')
        self.assertEqual(values['messages lost'], '0')
        self.assertNotEqual(level, DiagnosticStatus.ERROR)
        files = log_format.window_files(directory)
        self.assertEqual(len(files), int(values['windows saved']))
        self.assertGreaterEqual(len(files), 2)

    def test_3_enospc_keeps_windows_and_the_node_running(self):
        directory = os.path.join(self.disk, 'full')
        os.makedirs(directory)
        filler = os.path.join(self.disk, 'filler_full')
        self.start(directory)
        fill(filler, 0)  # to the last byte
        self.stream.publish(1.5, 500.0)
        level, message, values = self.wait_status(
            lambda level, message, values: int(values.get('windows held', 0)) >= 2, 'windows held after ENOSPC')
        self.assertEqual(level, DiagnosticStatus.ERROR)
        self.assertIn('No space left on device', message)
        self.assertIsNone(self.node.poll())
        self.assertEqual([p for p in os.listdir(directory) if log_format.TMP_MARK in p], [])
        os.unlink(filler)
        level, message, values = self.wait_status(
            lambda level, message, values: values.get('windows held') == '0' and values.get('writer queue') == '0'
            and values.get('intake queue') == '0' and len(log_format.window_files(directory)) == int(
                values.get('windows saved', -1)), 'the held windows to be written after ENOSPC')
        self.assertEqual(values['messages lost'], '0')
        self.assertEqual(level, DiagnosticStatus.WARN)  # recovered write errors stay visible as a warning
        self.assertEqual(len(log_format.window_files(directory)), int(values['windows saved']))
        self.assertIsNone(self.node.poll())

    def test_4_full_disk_with_old_windows_over_the_quota_makes_room(self):
        directory = os.path.join(self.disk, 'quota_full')
        old = [log_format.write_window(window(2000, start=5000 * k), directory, 'json-xz')[0] for k in range(5)]
        for age, path in enumerate(reversed(old)):  # written a minute apart, oldest first
            os.utime(path, (time.time() - 60 * (age + 1),) * 2)
        quota = 2.5 * max(os.path.getsize(path) for path in old) / 1e6
        filler = os.path.join(self.disk, 'filler_quota')
        fill(filler, 0)  # to the last byte
        try:
            self.start(directory, '_max_disk_mb:=%g' % quota)
            sent = self.stream.publish(1.5, 500.0)
            level, message, values = self.wait_status(
                lambda level, message, values: values.get('intake queue') == '0' and values.get('writer queue') == '0'
                and values.get('messages seen') == str(2 * sent) and values.get('windows held') == '0'
                and int(values.get('windows saved', 0)) >= 2, 'windows written on the full disk', 30)
            # (files: the anomalies, closer than post, make one window, written in parts of max_window)
            deleted = int(values['windows deleted (quota)'])
            self.assertGreater(deleted, 0)
            self.assertEqual(values['messages lost'], '0')
            code, out, err = fx.stop(self.node)
            type(self).node = None
            self.assertNotIn('still failing at close', out + err)  # what the node says of a window lost at shutdown
            remaining = [path for path in old if os.path.exists(path)]
            self.assertEqual(remaining, old[len(old) - len(remaining):])  # the oldest went first
            new = [path for path in log_format.window_files(directory) if path not in old]
            kept = sum(len(log_format.read_window(path)[1]) for path in new)
            # everything but what came before the first window and the last IMU message (after the last odometry)
            dropped = int(values['messages not kept (outside every window)'])
            self.assertTrue(2 * sent - dropped - 1 <= kept <= 2 * sent - dropped, (kept, sent, dropped))
        finally:
            os.unlink(filler)
            shutil.rmtree(directory, ignore_errors=True)

    def test_5_collect_node_on_a_full_disk_holds_retries_and_recovers_leftovers(self):
        directory = os.path.join(self.disk, 'collect_full')
        planted = log_format.write_window(window(200), directory, 'json-xz')[0]
        leftover = planted + log_format.TMP_MARK + '999999999'  # as if its writer had been killed
        os.rename(planted, leftover)
        filler = os.path.join(self.disk, 'filler_collect')
        fill(filler, 0)
        name = 'collect_logger_disk'
        del self.diagnostics[:]
        type(self).node = fx.start('collect_logger.py', '__name:=' + name, 'odom:=disk_odom', '_topics:=disk_imu',
                                   '_directory:=' + directory, '_rotate:=300', '_window:=20', '_stride:=10',
                                   '_diagnostic_period:=0.2')
        try:
            status = lambda: fx.status_values(self.diagnostics, name)  # noqa: E731
            fx.wait_for(lambda: status()[0] is not None, 30, 'the collect node to start')
            fx.wait_for(lambda: self.stream.connected() and fx.subscribed('/disk_imu', '/' + name), 30,
                        'the collect node to subscribe')
            time.sleep(0.5)
            sent = self.stream.publish(1.5, 500.0)
            fx.wait_for(lambda: status()[2].get('messages seen') == str(2 * sent) and int(
                status()[2].get('windows held', 0)) >= 2 and status()[2].get('writer queue') == '0', 20,
                'files held after ENOSPC')
            level, message, values = status()
            self.assertEqual(level, DiagnosticStatus.ERROR)
            self.assertIn('No space left on device', message)
            self.assertEqual(values['messages lost'], '0')
            self.assertEqual(values['leftovers recovered'], '1')
            self.assertEqual([name for _, _, names in os.walk(directory) for name in names
                              if log_format.TMP_MARK in name], [])  # no empty leftovers of failed writes
            os.unlink(filler)  # space returns
            fx.wait_for(lambda: status()[2].get('windows held') == '0' and status()[2].get('writer queue') == '0',
                        20, 'the held files to be written')
            level, message, values = status()
            self.assertEqual(values['messages lost'], '0')
            self.assertEqual(level, DiagnosticStatus.WARN)  # low disk (a 2 MB tmpfs) or write errors, all retried
            code, out, err = fx.stop(self.node)
            type(self).node = None
            self.assertEqual(code, 0, err[-2000:])
            files = [path for path in log_format.window_files(directory) if path != planted]
            self.assertEqual(recovery.scan(directory), [])
            self.assertEqual(len(log_format.read_window(planted)[1]), 200)  # the leftover, recovered
            self.assertEqual(sum(len(log_format.read_window(path)[1]) for path in files), 2 * sent)
            vectors = os.listdir(os.path.join(directory, 'features', 'nominal'))
            self.assertEqual(len(vectors), int(values['vectors written']))
            self.assertGreater(len(vectors), 0)
        finally:
            if os.path.exists(filler):
                os.unlink(filler)
            shutil.rmtree(directory, ignore_errors=True)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'reliability_disk', DiskTest)

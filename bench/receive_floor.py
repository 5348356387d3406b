#!/usr/bin/env python3
"""The receive floor of a Python node: CPU per message of rospy's own TCPROS receive (what the smart node's
intake runs on every subscription) against the least a Python reader can do (``recv_into`` each message's bytes
into a buffer of its size), on a local socket, message sizes of the live benches.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/receive_floor.py              # 700 B odometry, 320 B IMU, 0.9 MB image, 0.9 MB cloud
    python3 bench/receive_floor.py --seconds 1  # shorter

Each case: a sender thread writes TCPROS-framed messages (4-byte length + bytes) of one size into one end of a
socketpair, one at a time (each once the reader has the one before, as a topic's messages come live;
``--saturated``: as fast as the reader takes them); the reader, in this thread, is either
- rospy: ``rospy.impl.tcpros_base.TCPROSTransport.receive_once`` on a ``TCPROSSub`` of ``rospy.AnyMsg``
  (rospy's code as a subscriber runs it: ``sock.recv(buff_size)`` into a BytesIO, then ``read_messages`` cuts
  each message out), with ``buff_size`` 64 kB and 1 MB; or
- floor: ``recv_into`` the length, then ``recv_into`` a bytearray of that length (one copy, from the kernel);
- cc_log: ``nodes.tcpros_receive.FrameReader.read`` (what the intake runs with ``~fast_receive``: 64 kB
  ``recv_into`` a reused buffer, a larger message ``recv_into`` a bytearray of its size).
Figures: the reader's thread CPU time (``time.thread_time``) per message, and per MB; the sender's is apart.
"""
import argparse
import os
import socket
import struct
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

SIZES = (('odometry', 700), ('IMU', 320), ('image 640x480 rgb8', 921641), ('cloud 28,800 points', 921642))


def send(sock, size, stop, paced):
    """Send framed messages of ``size`` bytes until ``stop``: as fast as the socket takes them, or, ``paced`` (an
    Event), one message each time it is set (the reader sets it when it has read one)."""
    frame = struct.pack('<I', size) + bytes(size)
    frames = frame if paced else frame * max(1, (1 << 20) // len(frame))
    try:
        while not stop.is_set():
            if paced:
                if not paced.wait(0.5):
                    continue
                paced.clear()
            sock.sendall(frames)
    except OSError:
        pass


def rospy_reader(sock, buff_size):
    import rospy
    from rospy.impl.tcpros_base import TCPROSTransport
    from rospy.impl.tcpros_pubsub import TCPROSSub
    connection = TCPROSTransport(TCPROSSub('/bench', rospy.AnyMsg, buff_size=buff_size), '/bench')
    connection.socket = sock
    return lambda: len(connection.receive_once())


def floor_reader(sock):
    head = bytearray(4)
    view = memoryview(head)

    def read_exactly(target):
        view = memoryview(target)
        got = 0
        while got < len(target):
            got += sock.recv_into(view[got:])

    def read():
        read_exactly(view)
        body = bytearray(struct.unpack('<I', head)[0])
        read_exactly(body)
        return 1
    return read


def cc_log_reader(sock):
    from cc_log.nodes.tcpros_receive import FrameReader
    reader = FrameReader(sock, 1 << 31)

    def read():
        reader.read()
        return 1
    return read


def measure(size, reader_of, seconds, paced):
    """``(reader CPU seconds per message, messages)`` of ``seconds`` of reading messages of ``size`` bytes."""
    a, b = socket.socketpair()
    stop = threading.Event()
    go = threading.Event() if paced else None
    sender = threading.Thread(target=send, args=(a, size, stop, go), daemon=True)
    sender.start()
    read = reader_of(b)
    count = 0
    cpu0, wall0 = time.thread_time(), time.monotonic()
    while time.monotonic() - wall0 < seconds:
        if go is not None:
            go.set()
        count += read()
    cpu = time.thread_time() - cpu0
    stop.set()
    b.close()
    a.close()
    return cpu / count, count


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=3.0, help='of each case')
    parser.add_argument('--saturated', action='store_true',
                        help='the sender writes as fast as the reader reads (default: one message at a time, '
                        'each sent once the reader has the one before, as a topic\'s messages arrive live)')
    args = parser.parse_args(argv)
    common.header('Receive floor of a Python node', ['each case %g s on a socketpair, reader thread CPU time; %s'
                                                     % (args.seconds, 'saturated' if args.saturated else
                                                        'one message at a time')])
    readers = (('rospy 64 kB reads', lambda sock: rospy_reader(sock, 1 << 16)),
               ('rospy 1 MB reads', lambda sock: rospy_reader(sock, 1 << 20)),
               ('recv_into (floor)', floor_reader),
               ('cc_log FrameReader', cc_log_reader))
    rows = []
    for name, size in SIZES:
        row = [name, size]
        for _, reader_of in readers:
            per, _ = measure(size, reader_of, args.seconds, not args.saturated)
            row += ['%.1f' % (1e6 * per), '%.2f' % (per * 1e6 / size * 1e3)]
        rows.append(row)
    common.table(['message', 'bytes'] + ['%s %s' % (name, unit) for name, _ in readers
                                         for unit in ('us/msg', 'ms/MB')], rows,
                 'CPU per message received (reader thread):')
    return 0


if __name__ == '__main__':
    sys.exit(main())

#!/usr/bin/env python3
"""Held-out public robot logs (not in ../shared/data/real/): converted into rosbags for bench/detection_heldout.py.

    /usr/bin/python3 bench/heldout_data.py                        # every source into ~/.cache/cc_log/heldout
    /usr/bin/python3 bench/heldout_data.py --mirror DIR --out DIR # git dirs elsewhere, bags elsewhere
    /usr/bin/python3 bench/heldout_data.py --list                 # the sources, nothing written

Reads the sources straight out of bare git snapshots of their public repositories (``--mirror``, default
/work/.mirror: ``<owner>+<name>/repo``, as the search tool's ``fetch`` lays them; ``git show COMMIT:PATH``), and
writes one bag per run under ``--out`` (default ~/.cache/cc_log/heldout; never into the repository or
../shared), each with nav_msgs/Odometry on /odom (frame ``odom``, child ``base_link``, header stamp = bag time).
None of the sources carries an IMU at the odometry's rate, so no bag has one. The run's stamps start at
``EPOCH`` + the run's place in its robot's sequence (runs of one robot follow each other with a 10 s gap), so
the runs of one robot can be replayed one after the other.

Sources (repository @ commit : path, licence, robot, rate, length); the sha256 of each bag is in
bench/HELDOUT_SOURCES.md:

1. ``tuc`` -- an indoor mobile robot of TU Chemnitz (the TUC SLAM dataset, Neubert, Schubert & Protzel, RA-L 2019;
   the robot's model is not named in the readme), TUC-ProAut/libRSF @ d54801a232af02c0cda6012dabd3dea6c5fd77c5 :
   datasets/SLAM/Corridor_Input.txt and Lecture_Hall_Input.txt (``odom2`` lines: time, vx, vy, yaw rate), licence
   CC BY-NC-SA 4.0 (datasets/SLAM/LICENSE.txt). 10 Hz; corridor 2269 s (37.8 min, up to 0.42 m/s, 0.25 rad/s),
   lecture hall 1384 s (23.1 min, up to 0.66 m/s, 0.73 rad/s): a second place at a higher speed. The pose is
   the integral of the logged twist (the dataset's ground truth is a separate track; not used).
2. ``smartloc`` -- a passenger car in city traffic (the smartLoc dataset, TU Chemnitz; Reisdorf et al.),
   TUC-ProAut/libRSF @ d54801a232af02c0cda6012dabd3dea6c5fd77c5 : datasets/smartLoc/<run>_GT.txt (``point3``
   lines: time, ECEF x y z of the reference GNSS/INS), licence CC BY-SA 4.0 (datasets/smartLoc/LICENSE.txt).
   5 Hz (below the 10 Hz the motion features are tuned for; the only car log of >= 20 min found in git at any
   rate >= 4 Hz with a speed signal); runs Berlin Gendarmenmarkt 1193 s, Berlin Potsdamer Platz 283 s,
   Frankfurt Main Tower 1170 s, Frankfurt Westend Tower 715 s (56 min, up to ~10 m/s, stops at lights). The
   runs' ``_Input`` files (5 Hz speed and yaw rate) are 4 MB and more except Potsdamer Platz's, and are not in
   the snapshot, so the twist is derived from the reference positions: world velocity by central differences
   over ENU coordinates, heading = the direction of travel while faster than 0.5 m/s (held when slower, unwrapped),
   yaw rate its derivative, body twist = the world velocity turned into the heading. Berlin Gendarmenmarkt has
   position steps of up to 22 m/s between two samples (urban canyon): real oddities of the reference, kept.
3. ``mrclam`` -- five iRobot Create robots in one indoor room (UTIAS Multi-Robot Cooperative Localization and
   Mapping dataset, Leung et al. 2011, dataset 1), as committed by sethgi/sLAmCROIX @
   570c04fc92b71e339760b97157b17da2c412fccf : MRCLAM_Dataset1/Robot{1..5}_Odometry.dat (time, forward velocity,
   angular velocity), licence none stated (neither the repository nor the files state one). About 66 Hz on
   average, irregular (10-40 ms steps); 1490 s per robot (24.8 min, up to 0.09 m/s, 0.4 rad/s); a logged
   velocity of 0 for one sample about once a second (a logging artefact of the source, kept). The pose is the
   integral of the logged velocities (the Vicon ground truth files are over 4 MB and not in the snapshot).

Data files are never committed to this repository.
"""
import argparse
import hashlib
import math
import os
import subprocess
import sys

import numpy as np

EPOCH = 1.6e9          # the first run of every robot starts here (message time, s)
RUN_GAP = 10.0         # s between two runs of one robot
MIRROR = '/work/.mirror'
OUT = os.path.join('~', '.cache', 'cc_log', 'heldout')
TOPIC = '/odom'

LIBRSF = ('TUC-ProAut/libRSF', 'd54801a232af02c0cda6012dabd3dea6c5fd77c5')
SLAMCROIX = ('sethgi/sLAmCROIX', '570c04fc92b71e339760b97157b17da2c412fccf')

# robot -> (description, licence, [(run name, repository, commit, path, parser)])
ROBOTS = {
    'tuc': ('indoor mobile robot, TU Chemnitz (TUC SLAM dataset)', 'CC BY-NC-SA 4.0', [
        ('tuc_corridor', LIBRSF, 'datasets/SLAM/Corridor_Input.txt', 'odom2'),
        ('tuc_lecture_hall', LIBRSF, 'datasets/SLAM/Lecture_Hall_Input.txt', 'odom2'),
    ]),
    'smartloc': ('passenger car, city traffic (smartLoc, TU Chemnitz)', 'CC BY-SA 4.0', [
        ('smartloc_berlin_gendarmenmarkt', LIBRSF, 'datasets/smartLoc/Berlin_Gendarmenmarkt_GT.txt', 'point3'),
        ('smartloc_berlin_potsdamer_platz', LIBRSF, 'datasets/smartLoc/Berlin_Potsdamer_Platz_GT.txt', 'point3'),
        ('smartloc_frankfurt_main_tower', LIBRSF, 'datasets/smartLoc/Frankfurt_Main_Tower_GT.txt', 'point3'),
        ('smartloc_frankfurt_westend_tower', LIBRSF, 'datasets/smartLoc/Frankfurt_Westend_Tower_GT.txt', 'point3'),
    ]),
    'mrclam': ('iRobot Create, indoor room (UTIAS MRCLAM dataset 1)', 'none stated', [
        ('mrclam1_robot%d' % k, SLAMCROIX, 'MRCLAM_Dataset1/Robot%d_Odometry.dat' % k, 'vw') for k in range(1, 6)
    ]),
}
ORDER = ('tuc', 'smartloc', 'mrclam')


def git_dir(mirror, repo):
    """The bare git directory of ``repo`` (owner/name) under ``mirror`` (``owner+name/repo``, or its ``.git``)."""
    base = os.path.join(mirror, repo.replace('/', '+'), 'repo')
    return os.path.join(base, '.git') if os.path.isdir(os.path.join(base, '.git')) else base


def source_text(mirror, repo, commit, path):
    """The file at ``commit`` of the snapshot (ValueError naming what is missing)."""
    try:
        return subprocess.run(['git', '--git-dir', git_dir(mirror, repo), 'show', '%s:%s' % (commit, path)],
                              check=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE).stdout.decode()
    except (OSError, subprocess.CalledProcessError) as error:
        detail = getattr(error, 'stderr', b'') or b''
        raise ValueError('%s @ %s : %s: cannot be read from %s (%s)' % (
            repo, commit[:8], path, git_dir(mirror, repo), detail.decode(errors='replace').strip() or error))


def tagged_rows(text, tag):
    """The numbers of the lines that start with ``tag`` (libRSF's text format)."""
    return np.array([[float(v) for v in line.split()[1:]] for line in text.splitlines()
                     if line.startswith(tag + ' ')])


def integrate(t, vx, vy, wz):
    """Planar pose (x, y, yaw) integrated from body twist (midpoint heading)."""
    x, y, yaw = np.zeros(len(t)), np.zeros(len(t)), np.zeros(len(t))
    for i in range(1, len(t)):
        dt = t[i] - t[i - 1]
        mid = yaw[i - 1] + 0.5 * wz[i - 1] * dt
        x[i] = x[i - 1] + (vx[i - 1] * math.cos(mid) - vy[i - 1] * math.sin(mid)) * dt
        y[i] = y[i - 1] + (vx[i - 1] * math.sin(mid) + vy[i - 1] * math.cos(mid)) * dt
        yaw[i] = yaw[i - 1] + wz[i - 1] * dt
    return x, y, yaw


def from_odom2(text):
    """TUC SLAM ``odom2``: time, vx, vy, yaw rate (body frame)."""
    rows = tagged_rows(text, 'odom2')
    t, vx, vy, wz = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    x, y, yaw = integrate(t, vx, vy, wz)
    zero = np.zeros(len(t))
    return dict(t=t, x=x, y=y, z=zero, yaw=yaw, vx=vx, vy=vy, vz=zero, wz=wz)


def from_vw(text):
    """MRCLAM odometry: time, forward velocity, angular velocity."""
    rows = np.array([[float(v) for v in line.split()] for line in text.splitlines()
                     if line.strip() and not line.startswith('#')])
    rows = rows[np.argsort(rows[:, 0], kind='stable')]
    t, v, w = rows[:, 0] - rows[0, 0], rows[:, 1], rows[:, 2]
    zero = np.zeros(len(t))
    x, y, yaw = integrate(t, v, zero, w)
    return dict(t=t, x=x, y=y, z=zero, yaw=yaw, vx=v, vy=zero, vz=zero, wz=w)


MOVING = 0.5  # m/s: the direction of travel is the heading only above this speed


def from_point3(text):
    """smartLoc ``point3`` reference positions (ECEF) -> ENU pose and derived body twist (module docstring)."""
    rows = tagged_rows(text, 'point3')
    t, ecef = rows[:, 0], rows[:, 1:4]
    lon = math.atan2(ecef[0, 1], ecef[0, 0])
    lat = math.atan2(ecef[0, 2], math.hypot(ecef[0, 0], ecef[0, 1]))
    d = ecef - ecef[0]
    east = -math.sin(lon) * d[:, 0] + math.cos(lon) * d[:, 1]
    north = (-math.sin(lat) * math.cos(lon) * d[:, 0] - math.sin(lat) * math.sin(lon) * d[:, 1]
             + math.cos(lat) * d[:, 2])
    up = (math.cos(lat) * math.cos(lon) * d[:, 0] + math.cos(lat) * math.sin(lon) * d[:, 1]
          + math.sin(lat) * d[:, 2])
    ve, vn, vu = (np.gradient(c, t) for c in (east, north, up))
    speed = np.hypot(ve, vn)
    heading = np.zeros(len(t))
    last = math.atan2(vn[np.argmax(speed > MOVING)], ve[np.argmax(speed > MOVING)]) if (speed > MOVING).any() else 0.0
    for i in range(len(t)):
        if speed[i] > MOVING:
            last = math.atan2(vn[i], ve[i])
        heading[i] = last
    yaw = np.unwrap(heading)
    wz = np.gradient(yaw, t)
    vx = np.cos(yaw) * ve + np.sin(yaw) * vn
    vy = -np.sin(yaw) * ve + np.cos(yaw) * vn
    return dict(t=t - t[0], x=east, y=north, z=up, yaw=yaw, vx=vx, vy=vy, vz=vu, wz=wz)


PARSERS = {'odom2': from_odom2, 'vw': from_vw, 'point3': from_point3}


def odometry_messages(track, start):
    """(stamp, nav_msgs/Odometry) of a parsed track, stamps from ``start``."""
    import rospy
    from nav_msgs.msg import Odometry
    out = []
    for i in range(len(track['t'])):
        stamp = start + float(track['t'][i])
        msg = Odometry()
        msg.header.seq = i
        msg.header.stamp = rospy.Time.from_sec(stamp)
        msg.header.frame_id = 'odom'
        msg.child_frame_id = 'base_link'
        p = msg.pose.pose
        p.position.x, p.position.y, p.position.z = (float(track[k][i]) for k in ('x', 'y', 'z'))
        half = 0.5 * float(track['yaw'][i])
        p.orientation.z, p.orientation.w = math.sin(half), math.cos(half)
        tw = msg.twist.twist
        tw.linear.x, tw.linear.y, tw.linear.z = (float(track[k][i]) for k in ('vx', 'vy', 'vz'))
        tw.angular.z = float(track['wz'][i])
        out.append((stamp, msg))
    return out


def sha256(path):
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for block in iter(lambda: stream.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


def bag_path(out, name):
    return os.path.join(os.path.expanduser(out), name + '.bag')


def convert(mirror=MIRROR, out=OUT, robots=ORDER, log=print):
    """Write every run of ``robots`` as a bag under ``out``; return [(robot, run, path, messages, seconds, rate,
    sha256)]."""
    import rosbag
    import rospy
    out = os.path.expanduser(out)
    os.makedirs(out, exist_ok=True)
    rows = []
    for robot in robots:
        start = EPOCH
        for name, (repo, commit), path, parser in ROBOTS[robot][2]:
            track = PARSERS[parser](source_text(mirror, repo, commit, path))
            messages = odometry_messages(track, start)
            target = bag_path(out, name)
            with rosbag.Bag(target + '.tmp', 'w') as bag:
                for stamp, msg in messages:
                    bag.write(TOPIC, msg, rospy.Time.from_sec(stamp))
            os.replace(target + '.tmp', target)
            seconds = float(track['t'][-1] - track['t'][0])
            row = (robot, name, target, len(messages), seconds, (len(messages) - 1) / seconds, sha256(target))
            rows.append(row)
            log('%-10s %-34s %6d msgs %7.1f s %5.1f Hz  %s' % (row[:2] + row[3:6] + (row[6][:16],)))
            start += seconds + RUN_GAP
    return rows


def runs(robot, out=OUT):
    """The bag paths of a robot's runs, in order."""
    return [bag_path(out, name) for name, _, _, _ in ROBOTS[robot][2]]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--mirror', default=MIRROR, help='where the bare git snapshots are (default %s)' % MIRROR)
    parser.add_argument('--out', default=OUT, help='where the bags go (default %s)' % OUT)
    parser.add_argument('--robots', default=','.join(ORDER), help='comma-separated: %s' % ', '.join(ORDER))
    parser.add_argument('--list', action='store_true', help='print the sources and exit')
    args = parser.parse_args(argv)
    robots = args.robots.split(',')
    if args.list:
        for robot in robots:
            what, licence, items = ROBOTS[robot]
            for name, (repo, commit), path, _ in items:
                print('%-10s %-34s %s @ %s : %s (%s; %s)' % (robot, name, repo, commit, path, licence, what))
        return 0
    try:
        rows = convert(args.mirror, args.out, robots)
    except ValueError as error:
        sys.stderr.write('heldout_data: %s\n' % error)
        return 1
    print('\n| bag | robot | messages | seconds | Hz | sha256 |\n|---|---|---|---|---|---|')
    for robot, name, path, count, seconds, rate, digest in rows:
        print('| %s.bag | %s | %d | %.0f | %.1f | %s |' % (name, robot, count, seconds, rate, digest))
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""``cclog learn-envelope``: the physics envelope of nominal driving, for the ``envelope`` trigger."""
import argparse

from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, driving_topic, existing_file, output_flags, parent_exists, print_json, say,
    span)


def add_parser(subparsers):
    """The ``cclog learn-envelope`` sub-parser."""
    p = subparsers.add_parser('learn-envelope', **command_help(
        'the physics envelope of nominal bags, for a trigger of kind envelope',
        """
        Read the odometry (nav_msgs/Odometry) of nominal bags, compute the 19 envelope features (max speed,
        yaw rate, accelerations, jerk, pose and heading against the twist, standing still, speed drops...)
        over windows of --window every --stride, and write the largest value of each to --out (JSON). A
        trigger of kind envelope in the configuration (limits: that file) then flags every window where a
        feature exceeds its factor (default 2) times that maximum, floored by a physical minimum per feature.
        It learns the joint check too (unless --no-joint): how far from typical driving, all 19 features
        together, the windows went (a robust Mahalanobis distance); a window 4 times farther than any of them
        (the trigger's joint_factor) is flagged although each feature stays inside its limit. And the local
        part (unless --no-local): the distinct training windows (at most 10,000, evenly subsampled beyond),
        standardised, for their local outlier factor (20 neighbours); a window 6 times further past typical
        than any of them (local_factor) is flagged: a sparse gap between kinds of driving. The file is the
        default trigger where a model is given: smart_logger.py _model:=envelope.json, cclog replay --model.
        Only the bags set the envelope: give nominal driving only (docs/DETECTION.md, "The physics envelope").
        """,
        """
          cclog learn-envelope nominal.bag --out envelope.json
          cclog learn-envelope nominal.bag --topic /husky_velocity_controller/odom --out envelope.json
          cclog learn-envelope day1.bag day2.bag --topic /odom --out envelope.json --json
        """))
    p.add_argument('bag', nargs='+', metavar='BAG', help='a bag of nominal driving (indexed, rosbag 2.0)')
    p.add_argument('--topic', metavar='T', help="the odometry topic (nav_msgs/Odometry; default: the first bag's "
                   'only one)')
    p.add_argument('--out', required=True, metavar='PATH', help='the envelope file to write (JSON)')
    p.add_argument('--window', type=span('window'), default='1s', metavar='Ns',
                   help='feature window, a duration (default: %(default)s)')
    p.add_argument('--stride', type=span('stride'), default='250ms', metavar='Ns',
                   help='a window every this much message time (default: %(default)s)')
    p.add_argument('--joint', action=argparse.BooleanOptionalAction, default=True,
                   help='learn the joint check too (default: yes; --no-joint: the per-feature limits only)')
    p.add_argument('--local', action=argparse.BooleanOptionalAction, default=True,
                   help='learn the local part too (default: yes; --no-local: without it)')
    output_flags(p)
    return p


def _seconds(value, name):
    from cc_log.base.spans import Span
    parsed = Span.parse(value, name)
    if not parsed.is_duration or not 0 < parsed.seconds <= 600:
        raise CommandError('%s: %s must be a duration up to 10 minutes, like 1s or 250ms' % (name, value))
    return parsed.seconds


def learn_bags(paths, topic, window, stride, joint=True, local=True):
    """The ``Envelope`` of the odometry of ``topic`` in the bags ``paths`` (each bag's windows apart; with its
    joint check when ``joint``, its local part when ``local``, and the windows allow it)."""
    from cc_log.learning import envelope
    from cc_log.features.envelope import envelope_windows, odometry_samples
    from cc_log.features.motion import ODOMETRY
    from cc_log.offline import replay
    from cc_log.storage.bag import bag_reader
    matrices, seconds = [], 0.0
    for path in paths:
        replay.check_bag_topics(path, [topic], {topic: ODOMETRY})
        samples = odometry_samples(bag_reader.read_raw(path, [topic]))
        matrices.append(envelope_windows(*samples, window=window, stride=stride)[1])
        if len(samples[0]) > 1:
            seconds += float(samples[0].max() - samples[0].min())
    return envelope.learn(matrices, topic, window, stride, seconds, joint, local)


def run(args):
    """Learn the envelope of the bags and write it to --out."""
    from cc_log.learning.envelope import DEFAULT_FACTOR, DEFAULT_JOINT_FACTOR, DEFAULT_LOCAL_FACTOR, joint_shortfall
    from cc_log.learning.local_density import MAX_WINDOWS, shortfall
    from cc_log.features.envelope import ENVELOPE_COLUMNS, ENVELOPE_UNITS
    from cc_log.features.motion import ODOMETRY
    paths = [existing_file(path, 'bag file') for path in args.bag]
    parent_exists(args.out, 'out')
    window, stride = _seconds(args.window, 'window'), _seconds(args.stride, 'stride')
    if args.topic is None:
        args.bag = paths[0]
        args.topic = driving_topic(args, ODOMETRY)
    learned = learn_bags(paths, args.topic, window, stride, args.joint, args.local)
    learned.save(args.out)
    if args.json:
        document = learned.to_dict()
        if learned.local is not None:  # its training windows stay in the file: a summary here
            document['local'] = learned.local.summary()
        document['out'] = args.out
        print_json(document)
        return EXIT_OK
    say('envelope of %s in %d bag(s): %d windows of %g s every %g s, %.0f s of driving -> %s'
        % (args.topic, len(paths), learned.windows, window, stride, learned.seconds, args.out))
    trained, limits = learned.trained(), learned.limits(DEFAULT_FACTOR)
    print('%-20s %-8s %12s %12s %12s' % ('feature', 'unit', 'most seen', 'floored', 'limit at %gx' % DEFAULT_FACTOR))
    for name, floored, limit in zip(ENVELOPE_COLUMNS, trained, limits):
        print('%-20s %-8s %12.4g %12.4g %12.4g' % (name, ENVELOPE_UNITS[name], learned.maxima[name], floored, limit))
    joint = learned.joint
    if joint is not None:
        print('joint check over %d windows: squared distance from typical driving %.4g typical (median), %.4g '
              'farthest; flagged beyond %.4g (joint_factor %g)' % (
                  learned.windows, joint.typical, joint.farthest,
                  joint.typical + DEFAULT_JOINT_FACTOR * (joint.farthest - joint.typical), DEFAULT_JOINT_FACTOR))
    elif args.joint:
        print('no joint check: %s' % (joint_shortfall(learned.windows) or 'the training windows do not spread'))
    local = learned.local
    if local is not None:
        kept = len(local.training)
        print('local part over %d windows%s, %d neighbours: local outlier factor %.4g typical (median), %.4g the '
              'largest; flagged beyond %.4g (local_factor %g)' % (
                  kept, '' if kept == learned.windows else ' (the distinct ones%s)' % (
                      ', evenly subsampled' if kept == MAX_WINDOWS else ''), local.k,
                  -local.typical, -local.extreme,
                  -local.typical + DEFAULT_LOCAL_FACTOR * (local.typical - local.extreme), DEFAULT_LOCAL_FACTOR))
    elif args.local:
        print('no local part: %s' % (shortfall(min(learned.windows, MAX_WINDOWS)) or
                                     'the training windows all score alike'))
    return EXIT_OK

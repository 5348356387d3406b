"""``cclog plot``: a timeline of a run (PNG)."""
from cc_log.offline.progress import bar as _bar
from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, non_negative_int, output_flags, parent_exists, positive_float, print_json,
    read_windows)


def add_parser(subparsers):
    """The ``cclog plot`` sub-parser."""
    p = subparsers.add_parser('plot', **command_help(
        'timeline of a run with windows and scores (PNG)',
        """
        Draw a timeline: speed of the driving topic (nav_msgs/Odometry) over time with the saved windows
        shaded, and below it the classifier scores of the triggers and the model threshold. With --bag the
        speed curve covers the whole run, else only the messages inside the windows; with --bag and
        --model the model's score of every feature window of the run is drawn too; with --truth the true
        events, so a window that was or was not kept can be told from the score. Uses matplotlib's Agg
        backend (no display needed).
        """,
        """
          cclog plot logs --bag husky.bag --out run.png
          cclog plot logs --bag husky.bag --model model.json --out run-scores.png
          cclog plot logs/cc_log_20150521T191138.027Z_classifier.json.xz --out window.png
          cclog plot logs --bag sim.bag --model model.json --truth sim.bag.truth.json --out why.png
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='window file or directory')
    p.add_argument('--out', required=True, metavar='PNG', help='image to write')
    p.add_argument('--bag', metavar='BAG', help='the full run, for the speed curve')
    p.add_argument('--topic', metavar='T', help='driving topic (default: the windows\' driving_topic)')
    p.add_argument('--model', metavar='PATH', help='with --bag: draw this model\'s score over the whole run')
    p.add_argument('--truth', metavar='JSON', help='true events to draw: cclog simulate\'s <bag>.truth.json, or a '
                   'JSON list of {type, start, end}')
    p.add_argument('--stride', type=non_negative_int('stride', 1), default=1, metavar='N',
                   help='with --model: score every N-th message (default: %(default)s)')
    p.add_argument('--title', help='figure title')
    p.add_argument('--width', type=positive_float('width'), default=11.0, help='inches (default: %(default)s)')
    p.add_argument('--dpi', type=non_negative_int('dpi', 10), default=100, help='(default: %(default)s)')
    output_flags(p)
    return p


def run(args):
    """A timeline: speed of the driving topic with the saved windows shaded (and the true events of
    ``--truth``), and the scores with the threshold (``plot``)."""
    from cc_log.offline import plot
    windows = []
    driving = args.topic
    for path, metadata, records in read_windows(args, args.paths, 'plot'):
        driving = driving or metadata.get('driving_topic')
        windows.append((path, metadata, records))
    if not driving:
        raise CommandError('topic: the windows do not name their driving topic; give --topic')
    truth = plot.load_truth(args.truth) if args.truth else []
    if args.bag:
        from cc_log.storage.bag import bagio
        bag = bagio.open_bag(args.bag)
        try:
            bagio.check_topic(bag, driving, plot.ODOMETRY)
            total = bag.get_message_count([driving])
        finally:
            bag.close()
        speed = []
        with _bar(args, 'read', total) as bar:
            for record in bagio.read_messages(args.bag, [driving], {driving: plot.ODOMETRY}):
                speed.append((record.stamp,) + plot.motion_of(record.msg))
                bar.update()
    else:
        speed = plot.window_speeds(windows, driving)
        if not any(speed):
            raise CommandError('topic: no nav_msgs/Odometry messages on %s in the windows' % driving)
    curve, threshold = [], None
    if args.model:
        from cc_log.learning.model import AnomalyModel
        if not args.bag:
            raise CommandError('model: --model scores the whole run and needs --bag')
        model = AnomalyModel.load(args.model)
        threshold = model.threshold
        with _bar(args, 'score').busy():
            curve = plot.run_scores(args.bag, driving, model, args.stride)
    parent_exists(args.out, 'out')
    title = args.title or '%s: %d saved window(s)%s' % (
        args.bag or ', '.join(args.paths), len(windows), '' if args.bag else ' (speed inside the windows only)')
    summary = plot.timeline(args.out, windows, speed, curve, threshold, truth, title, args.width, args.dpi,
                            'speed (%s)' % driving)
    if args.json:
        print_json(summary)
    else:
        print('%s: %d window(s), %d trigger score(s), %d speed samples%s' % (
            args.out, len(windows), summary['triggers'], summary['speed_samples'],
            ', %d of %d true events inside windows' % (summary['truth_in_windows'], len(truth)) if truth else ''))
    return EXIT_OK

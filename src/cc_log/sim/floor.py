"""The floor the simulated BWIBot tours, and the route it follows.

``FloorPlan.bwi_floor()``: a fixed office floor as a graph (corridors around a loop, offices and a lab behind
doors, an elevator lobby and an open atrium), routed time-shortest (Dijkstra). ``Path``: a route as a polyline
with per-segment speed limits, slowing for corners and the goal, followed by pure pursuit (``world``).
"""
import collections
import heapq
import math

from cc_log.sim.kinematics import wrap

PLANNED_DECEL = 0.5          # braking the planner plans with (m/s^2), below the limit


class FloorPlan(object):
    """A building floor as a graph: named nodes at (x, y) metres, edges with a kind that sets the speed."""

    SPEEDS = {'corridor': 1.0, 'passage': 0.8, 'atrium': 0.8, 'door': 0.35, 'room': 0.5}

    def __init__(self, nodes, edges, destinations, start):
        self.nodes = dict(nodes)
        self.edges = list(edges)
        self.destinations = list(destinations)
        self.start = start
        self._adjacent = collections.defaultdict(list)
        for a, b, kind in self.edges:
            if a not in self.nodes or b not in self.nodes or kind not in self.SPEEDS:
                raise ValueError('floor: bad edge %r' % ((a, b, kind),))
            length = math.hypot(self.nodes[b][0] - self.nodes[a][0], self.nodes[b][1] - self.nodes[a][1])
            self._adjacent[a].append((b, kind, length))
            self._adjacent[b].append((a, kind, length))

    @classmethod
    def bwi_floor(cls):
        """An office floor after the BWI lab's (Gates Dell Complex): a 40 m x 20 m corridor loop with a
        central corridor and elevator lobby, offices, lab, kitchen and conference room behind doors, and an
        open atrium east of the loop."""
        nodes = {
            'S0': (0.0, 0.0), 'S1': (10.0, 0.0), 'S2': (20.0, 0.0), 'S3': (30.0, 0.0), 'S4': (40.0, 0.0),
            'N0': (0.0, 20.0), 'N1': (10.0, 20.0), 'N2': (20.0, 20.0), 'N3': (30.0, 20.0), 'N4': (40.0, 20.0),
            'W1': (0.0, 10.0), 'E1': (40.0, 10.0), 'LOBBY': (20.0, 10.0),
            'ATRIUM_GATE': (44.0, 10.0), 'ATRIUM': (52.0, 10.0), 'ATRIUM_SW': (48.0, 4.0),
            'ATRIUM_NW': (48.0, 16.0), 'ATRIUM_SE': (56.0, 4.0), 'ATRIUM_NE': (56.0, 16.0),
            'LAB_DOOR': (-1.2, 10.0), 'LAB': (-5.0, 10.0),
            'OFFICE1_DOOR': (10.0, -1.2), 'OFFICE1': (10.0, -4.5),
            'OFFICE2_DOOR': (30.0, -1.2), 'OFFICE2': (30.0, -4.5),
            'OFFICE3_DOOR': (10.0, 21.2), 'OFFICE3': (10.0, 24.5),
            'KITCHEN_DOOR': (30.0, 21.2), 'KITCHEN': (30.0, 24.5),
            'CONFERENCE_DOOR': (21.2, 10.0), 'CONFERENCE': (25.0, 10.0),
        }
        corridor = [('S0', 'S1'), ('S1', 'S2'), ('S2', 'S3'), ('S3', 'S4'), ('N0', 'N1'), ('N1', 'N2'),
                    ('N2', 'N3'), ('N3', 'N4'), ('S0', 'W1'), ('W1', 'N0'), ('S4', 'E1'), ('E1', 'N4'),
                    ('S2', 'LOBBY'), ('LOBBY', 'N2')]
        atrium = [('ATRIUM_GATE', 'ATRIUM'), ('ATRIUM_GATE', 'ATRIUM_SW'), ('ATRIUM_GATE', 'ATRIUM_NW'),
                  ('ATRIUM', 'ATRIUM_SW'), ('ATRIUM', 'ATRIUM_NW'), ('ATRIUM', 'ATRIUM_SE'),
                  ('ATRIUM', 'ATRIUM_NE'), ('ATRIUM_SW', 'ATRIUM_SE'), ('ATRIUM_NW', 'ATRIUM_NE'),
                  ('ATRIUM_SE', 'ATRIUM_NE')]
        rooms = [('W1', 'LAB'), ('S1', 'OFFICE1'), ('S3', 'OFFICE2'), ('N1', 'OFFICE3'), ('N3', 'KITCHEN'),
                 ('LOBBY', 'CONFERENCE')]
        edges = [(a, b, 'corridor') for a, b in corridor] + [(a, b, 'atrium') for a, b in atrium]
        edges.append(('E1', 'ATRIUM_GATE', 'passage'))
        for hall, room in rooms:
            edges.append((hall, room + '_DOOR', 'door'))
            edges.append((room + '_DOOR', room, 'room'))
        destinations = ['LAB', 'OFFICE1', 'OFFICE2', 'OFFICE3', 'KITCHEN', 'CONFERENCE', 'LOBBY', 'ATRIUM',
                        'ATRIUM_SE', 'ATRIUM_NE']
        return cls(nodes, edges, destinations, start='LAB')

    def route(self, start, goal):
        """Shortest route from node ``start`` to node ``goal``: (node names, kinds of the edges)."""
        queue = [(0.0, start)]
        best = {start: (0.0, None, None)}
        done = set()
        while queue:
            cost, node = heapq.heappop(queue)
            if node in done:
                continue
            done.add(node)
            if node == goal:
                break
            for other, kind, length in sorted(self._adjacent[node]):
                new = cost + length / self.SPEEDS[kind]   # time-shortest
                if other not in best or new < best[other][0] - 1e-12:
                    best[other] = (new, node, kind)
                    heapq.heappush(queue, (new, other))
        if goal not in done:
            raise ValueError('floor: no route from %s to %s' % (start, goal))
        names, kinds = [goal], []
        while names[-1] != start:
            _, previous, kind = best[names[-1]]
            names.append(previous)
            kinds.append(kind)
        return names[::-1], kinds[::-1]


class Path(object):
    """A polyline with per-segment speed limits, followed by pure pursuit."""

    def __init__(self, points, speeds, limits):
        self.points = points
        self.speeds = speeds
        self.lengths = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:])]
        self.cumulative = [0.0]
        for length in self.lengths:
            self.cumulative.append(self.cumulative[-1] + length)
        self.total = self.cumulative[-1]
        corner = [0.0] * len(points)   # speed allowed at each vertex
        for j in range(1, len(points) - 1):
            a, b, c = points[j - 1], points[j], points[j + 1]
            turn = abs(wrap(math.atan2(c[1] - b[1], c[0] - b[0]) - math.atan2(b[1] - a[1], b[0] - a[0])))
            corner[j] = max(0.15, min(speeds[j - 1], speeds[j]) * max(0.0, 1.0 - turn / (0.55 * math.pi)))
        self.corner = corner
        self.segment = 0
        self.limits = limits

    def progress(self, x, y):
        """Advance along the path to the robot's projection; return the arc length there."""
        while True:
            i = self.segment
            a, b = self.points[i], self.points[i + 1]
            length = self.lengths[i]
            along = ((x - a[0]) * (b[0] - a[0]) + (y - a[1]) * (b[1] - a[1])) / length if length > 1e-9 else length
            if along >= length and i + 2 < len(self.points):
                self.segment += 1
                continue
            return self.cumulative[i] + min(max(along, 0.0), length)

    def point_at(self, s):
        """The point at arc length ``s`` (clamped to the path)."""
        s = min(max(s, 0.0), self.total)
        i = self.segment
        while i + 1 < len(self.lengths) and self.cumulative[i + 1] < s:
            i += 1
        a, b = self.points[i], self.points[i + 1]
        f = (s - self.cumulative[i]) / self.lengths[i] if self.lengths[i] > 1e-9 else 1.0
        return a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])

    def speed_at(self, s):
        """Target speed at arc length s: segment limit, braking for the coming corners and the goal."""
        i = self.segment
        speed = self.speeds[i]
        for j in range(i + 1, min(i + 6, len(self.points))):
            ahead = max(0.0, self.cumulative[j] - s - (0.05 if j == len(self.points) - 1 else 0.0))
            speed = min(speed, math.sqrt(self.corner[j] ** 2 + 2.0 * PLANNED_DECEL * ahead))
        return speed

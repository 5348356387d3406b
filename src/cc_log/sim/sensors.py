"""The camera and the laser scanner of the simulated BWIBot (``cc_log.sim``): heavy sensors to log.

The floor plan's graph is turned into walls once (``WallMap``: an occupancy grid of 10 cm cells; corridors,
doors and passages carved as rectangles along the graph's edges, a box around every room, the atrium as one
open hall); both sensors ray-cast it from the robot's true pose with numpy:

- ``sensor_msgs/Image`` on ``/camera/image_raw`` (``rgb8``, 320 x 240, 60 degrees wide, 1 m above the floor,
  ``CAMERA_RATE`` Hz): walls coloured by the space they face, shaded by side and distance, with a dark band every
  2 m and a baseboard; a checkered floor (1 m tiles) and a plain ceiling, so every frame shows where the robot is.
- ``sensor_msgs/LaserScan`` on ``/scan`` (240 degrees, 0.5 degree steps, ``SCAN_RATE`` Hz): ranges to the
  walls with 1 cm of seeded noise, ``inf`` where nothing is within ``range_max`` (REP 117).

During a collision an obstacle (a red box, 0.5 m) stands right in front of the base: the scan's middle beams
read ~0.3 m and the middle of the image turns red. Everything is deterministic (a seeded numpy generator).
"""
import itertools
import math

import numpy
from sensor_msgs.msg import Image, LaserScan
from std_msgs.msg import Header

CAMERA_TOPIC = '/camera/image_raw'
SCAN_TOPIC = '/scan'
CAMERA_RATE = 15.0
SCAN_RATE = 10.0
CAMERA_FRAME = 'camera_link'
LASER_FRAME = 'laser'
WIDTH, HEIGHT = 320, 240
FIELD_OF_VIEW = math.radians(60.0)
CAMERA_HEIGHT = 1.0            # m above the floor
WALL_HEIGHT = 2.5              # m
SCAN_HALF_ANGLE = math.radians(120.0)
SCAN_STEP = math.radians(0.5)
SCAN_MIN, SCAN_MAX = 0.05, 20.0
SCAN_NOISE = 0.01              # m
OBSTACLE_AHEAD = 0.55          # m from the base's centre to the obstacle's centre during a collision
OBSTACLE_HALF = 0.25           # m, half its side
CELL = 0.1                     # m, wall map resolution
HALF_WIDTHS = {'corridor': 1.2, 'passage': 1.0, 'atrium': 1.5, 'door': 0.5, 'room': 0.5}
ROOM_HALF = 2.5                # m, half the side of a room
ATRIUM_MARGIN = 2.0            # m around the atrium's nodes

_PALETTE = numpy.array([[205, 190, 160], [150, 180, 210], [170, 205, 160], [215, 175, 140], [190, 160, 205],
                        [200, 200, 130], [140, 200, 195], [220, 160, 170], [160, 160, 200]], dtype=numpy.float32)
_OBSTACLE_COLOUR = numpy.array([210, 30, 30], dtype=numpy.float32)
_OBSTACLE = -1                 # area id of an obstacle hit
_CEILING = numpy.array([225, 225, 220], dtype=numpy.float32)
_TILES = numpy.array([[120, 115, 105], [165, 160, 150]], dtype=numpy.float32)


class WallMap(object):
    """The floor plan as an occupancy grid: ``area`` holds, per 10 cm cell, 0 for a wall and the number of the
    space carved there (1: corridors and passages, then one per room, the atrium) otherwise."""

    def __init__(self, floor):
        xs = [p[0] for p in floor.nodes.values()]
        ys = [p[1] for p in floor.nodes.values()]
        margin = ROOM_HALF + 2.0
        self.x0, self.y0 = min(xs) - margin, min(ys) - margin
        self.nx = int(math.ceil((max(xs) + margin - self.x0) / CELL))
        self.ny = int(math.ceil((max(ys) + margin - self.y0) / CELL))
        self.area = numpy.zeros((self.nx, self.ny), dtype=numpy.int16)
        degree = {}
        for a, b, kind in floor.edges:
            for node in (a, b):
                degree.setdefault(node, set()).add(kind)
        atrium = [floor.nodes[n] for n, kinds in sorted(degree.items()) if 'atrium' in kinds]
        if atrium:
            self._carve_box(min(p[0] for p in atrium) - ATRIUM_MARGIN, min(p[1] for p in atrium) - ATRIUM_MARGIN,
                            max(p[0] for p in atrium) + ATRIUM_MARGIN, max(p[1] for p in atrium) + ATRIUM_MARGIN, 2)
        for a, b, kind in floor.edges:
            self._carve_segment(floor.nodes[a], floor.nodes[b], HALF_WIDTHS.get(kind, 0.5),
                                2 if kind == 'atrium' else 1)
        for number, (name, kinds) in enumerate(sorted(degree.items())):
            if kinds == {'room'} and len([e for e in floor.edges if name in e[:2]]) == 1:
                x, y = floor.nodes[name]
                self._carve_box(x - ROOM_HALF, y - ROOM_HALF, x + ROOM_HALF, y + ROOM_HALF, 3 + number)

    def _cells(self, x0, y0, x1, y1):
        """Index ranges and cell centres of the cells whose centres lie in a box."""
        i0, i1 = max(0, int(math.ceil((x0 - self.x0) / CELL - 0.5))), min(self.nx, int((x1 - self.x0) / CELL + 0.5))
        j0, j1 = max(0, int(math.ceil((y0 - self.y0) / CELL - 0.5))), min(self.ny, int((y1 - self.y0) / CELL + 0.5))
        cx = self.x0 + (numpy.arange(i0, i1) + 0.5) * CELL
        cy = self.y0 + (numpy.arange(j0, j1) + 0.5) * CELL
        return slice(i0, i1), slice(j0, j1), cx[:, None], cy[None, :]

    def _carve_box(self, x0, y0, x1, y1, area):
        si, sj, _, _ = self._cells(x0, y0, x1, y1)
        self.area[si, sj] = area

    def _carve_segment(self, a, b, half, area):
        """A rectangle along a -> b, ``half`` m to each side and beyond each end; cells carved before keep
        their area."""
        length = math.hypot(b[0] - a[0], b[1] - a[1])
        ux, uy = ((b[0] - a[0]) / length, (b[1] - a[1]) / length) if length > 1e-9 else (1.0, 0.0)
        si, sj, cx, cy = self._cells(min(a[0], b[0]) - half, min(a[1], b[1]) - half,
                                     max(a[0], b[0]) + half, max(a[1], b[1]) + half)
        along = (cx - a[0]) * ux + (cy - a[1]) * uy
        across = (cy - a[1]) * ux - (cx - a[0]) * uy
        inside = (along >= -half) & (along <= length + half) & (numpy.abs(across) <= half)
        block = self.area[si, sj]
        block[inside & (block == 0)] = area

    def lookup(self, x, y):
        """Area numbers at the points (arrays); 0 (wall) outside the map (its border cells are walls)."""
        i = ((x - self.x0) * (1.0 / CELL)).astype(numpy.int32)
        j = ((y - self.y0) * (1.0 / CELL)).astype(numpy.int32)
        numpy.clip(i, 0, self.nx - 1, out=i)
        numpy.clip(j, 0, self.ny - 1, out=j)
        return self.area[i, j]

    def cast(self, x, y, angles, max_range, obstacle=None, step=CELL):
        """Ray-cast from (x, y) along ``angles`` (radians): ``(distance, hit x, hit y, vertical, area)`` per
        ray: the distance to the first wall or obstacle (``inf`` beyond ``max_range``), where it was hit,
        whether the face hit runs along y, and the area number of the space it faces (``_OBSTACLE`` for the
        obstacle)."""
        cos, sin = numpy.cos(angles)[:, None], numpy.sin(angles)[:, None]
        samples = numpy.arange(1, int(max_range / step) + 2) * step
        blocked = self._blocked(x + cos * samples, y + sin * samples, obstacle)
        hit = blocked.any(axis=1)
        first = numpy.where(hit, blocked.argmax(axis=1), len(samples) - 1)
        # refine between the last free sample and the first blocked one, 5 mm at a time
        fine = (first[:, None] + numpy.linspace(-1.0, 0.0, int(round(step / 0.005)) + 1)[None, :]) * step + step
        fine_blocked = self._blocked(x + cos * fine, y + sin * fine, obstacle)
        fine_blocked[:, -1] = True
        distance = fine[numpy.arange(len(angles)), fine_blocked.argmax(axis=1)]
        distance = numpy.where(hit & (distance <= max_range), distance, numpy.inf)
        near = numpy.where(numpy.isfinite(distance), distance, max_range)
        hx, hy = x + cos[:, 0] * near, y + sin[:, 0] * near
        bx, by = x + cos[:, 0] * (near - 0.006), y + sin[:, 0] * (near - 0.006)   # just before the face
        vertical = self.lookup(hx, by) == 0     # the step along x alone reaches the wall: a face along y
        area = self.lookup(bx, by)
        if obstacle is not None:
            area = numpy.where(_in_box(hx, hy, obstacle) & (self.lookup(hx, hy) != 0), _OBSTACLE, area)
        return distance, hx, hy, vertical, area

    def _blocked(self, px, py, obstacle):
        blocked = self.lookup(px, py) == 0
        if obstacle is not None:
            blocked |= _in_box(px, py, obstacle)
        return blocked


def _in_box(px, py, box):
    cx, cy, yaw, half = box
    dx, dy = px - cx, py - cy
    c, s = math.cos(yaw), math.sin(yaw)
    return (numpy.abs(dx * c + dy * s) <= half) & (numpy.abs(dy * c - dx * s) <= half)


_MAPS = {}


def wall_map(floor):
    """The ``WallMap`` of a floor plan, built once per plan object."""
    key = id(floor)
    if key not in _MAPS or _MAPS[key][0] is not floor:
        _MAPS[key] = (floor, WallMap(floor))
    return _MAPS[key][1]


class Sensors(object):
    """The camera and the scanner of one simulated run: ``frames(...)`` gives what is due at a tick."""

    def __init__(self, floor, seed, rate, camera=True, scan=True):
        self.walls = wall_map(floor)
        self.camera = camera
        self.scan = scan
        self.rate = rate
        self._rng = numpy.random.default_rng(numpy.random.SeedSequence([int(seed) & 0xffffffff, 7]))
        self._frames, self._scans = itertools.count(), itertools.count()   # header seq numbers
        self._obstacle = None          # (start tick of the collision, box)
        self.focal = WIDTH / 2.0 / math.tan(FIELD_OF_VIEW / 2.0)
        self._columns = -numpy.arctan((numpy.arange(WIDTH) + 0.5 - WIDTH / 2.0) / self.focal)
        rows = numpy.arange(HEIGHT // 2, HEIGHT) + 0.5 - HEIGHT / 2.0
        self._floor_depth = (self.focal * CAMERA_HEIGHT / rows)[:, None]          # m straight ahead, per row
        self._floor = (_TILES[None, :, :] / (1.0 + 0.04 * self._floor_depth)[:, :, None]).astype(numpy.uint8)
        self._floor_rows = numpy.arange(len(rows))[:, None]
        fade = 0.75 + 0.25 * (1.0 - 1.0 / (1.0 + 0.02 * numpy.abs(rows[::-1])))
        self._ceiling = (_CEILING[None, None, :] * fade[:, None, None]).astype(numpy.uint8)
        self._rows = (numpy.arange(HEIGHT) + 0.5)[:, None]
        self._beams = numpy.arange(-SCAN_HALF_ANGLE, SCAN_HALF_ANGLE + SCAN_STEP / 2.0, SCAN_STEP)

    def frames(self, tick, stamp, stamp_s, pose, collision=None):
        """``[(topic, stamp_s, message)]`` due at ``tick`` (ticks at ``rate`` Hz): an Image each time the
        camera's 15 Hz clock passes a frame, a LaserScan each 10 Hz. ``pose``: the true (x, y, yaw);
        ``collision``: the start tick of a collision under way (an obstacle stands in front of the base)."""
        out = []
        obstacle = self._obstacle_for(collision, pose)
        if self.camera and self._due(tick, CAMERA_RATE):
            out.append((CAMERA_TOPIC, stamp_s, self.image(stamp, pose, obstacle)))
        if self.scan and self._due(tick, SCAN_RATE):
            out.append((SCAN_TOPIC, stamp_s, self.laser_scan(stamp, pose, obstacle)))
        return out

    def _due(self, tick, rate):
        return tick == 0 or int(tick * rate / self.rate) != int((tick - 1) * rate / self.rate)

    def _obstacle_for(self, collision, pose):
        if collision is None:
            self._obstacle = None
            return None
        if self._obstacle is None or self._obstacle[0] != collision:
            x, y, yaw = pose
            self._obstacle = (collision, (x + OBSTACLE_AHEAD * math.cos(yaw), y + OBSTACLE_AHEAD * math.sin(yaw),
                                          yaw, OBSTACLE_HALF))
        return self._obstacle[1]

    def render(self, pose, obstacle=None):
        """The camera's view from ``pose`` as a HEIGHT x WIDTH x 3 uint8 array."""
        x, y, yaw = pose
        angles = yaw + self._columns
        distance, hx, hy, vertical, area = self.walls.cast(x, y, angles, 30.0, obstacle)
        depth = numpy.maximum(numpy.where(numpy.isfinite(distance), distance, 30.0) * numpy.cos(self._columns), 0.05)
        top = HEIGHT / 2.0 - self.focal * (WALL_HEIGHT - CAMERA_HEIGHT) / depth
        bottom = HEIGHT / 2.0 + self.focal * CAMERA_HEIGHT / depth
        colour = numpy.where((area == _OBSTACLE)[:, None], _OBSTACLE_COLOUR, _PALETTE[numpy.abs(area) % len(_PALETTE)])
        along = numpy.where(vertical, hy, hx)
        band = (numpy.mod(along, 2.0) < 0.12) & (area != _OBSTACLE)
        shade = numpy.where(vertical, 1.0, 0.82) * numpy.where(band, 0.55, 1.0) / (1.0 + 0.04 * depth)
        wall = (colour * shade[:, None]).astype(numpy.uint8)                       # WIDTH x 3
        skirting = (wall * 0.45).astype(numpy.uint8)
        image = numpy.empty((HEIGHT, WIDTH, 3), dtype=numpy.uint8)
        image[:HEIGHT // 2] = self._ceiling
        ahead = self._floor_depth / numpy.cos(self._columns)[None, :]
        tiles = (numpy.floor(x + ahead * numpy.cos(angles)[None, :]) +
                 numpy.floor(y + ahead * numpy.sin(angles)[None, :])).astype(numpy.int64) & 1
        image[HEIGHT // 2:] = self._floor[self._floor_rows, tiles]
        rows = self._rows
        image = numpy.where(((rows >= top) & (rows < bottom))[:, :, None],
                            numpy.where((rows - top > 0.94 * (bottom - top))[:, :, None], skirting, wall), image)
        return image

    def image(self, stamp, pose, obstacle=None):
        """A sensor_msgs/Image (rgb8) of ``render``."""
        return Image(header=Header(seq=next(self._frames), stamp=stamp, frame_id=CAMERA_FRAME), height=HEIGHT,
                     width=WIDTH, encoding='rgb8', is_bigendian=0, step=WIDTH * 3,
                     data=self.render(pose, obstacle).tobytes())

    def ranges(self, pose, obstacle=None):
        """The scan's ranges from ``pose`` (float32 array; ``inf``: nothing within range)."""
        x, y, yaw = pose
        distance = self.walls.cast(x, y, yaw + self._beams, SCAN_MAX, obstacle)[0]
        noisy = distance + self._rng.normal(0.0, SCAN_NOISE, len(distance))
        return numpy.where(numpy.isfinite(distance), numpy.clip(noisy, SCAN_MIN, SCAN_MAX), numpy.inf).astype(
            numpy.float32)

    def laser_scan(self, stamp, pose, obstacle=None):
        """A sensor_msgs/LaserScan of ``ranges``."""
        return LaserScan(header=Header(seq=next(self._scans), stamp=stamp, frame_id=LASER_FRAME),
                         angle_min=float(self._beams[0]), angle_max=float(self._beams[-1]), angle_increment=SCAN_STEP,
                         time_increment=0.0, scan_time=1.0 / SCAN_RATE, range_min=SCAN_MIN, range_max=SCAN_MAX,
                         ranges=self.ranges(pose, obstacle).tolist())

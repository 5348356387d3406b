"""The floors of src/cc_log: each package of the library stands on the packages of the floors below it and imports
nothing from its own floor's other packages or from above (imports inside functions counted, as test_lint counts
them). FLOORS is the one statement of the order; docs/DESIGN.md draws it."""
import os

from test_lint import PACKAGE, cc_log_modules, imported_modules

# From the ground up; the packages of one floor stand side by side and do not import each other.
FLOORS = (
    ('base',),                  # records, grammar, registry, codecs, safe input and files, routes, errors
    ('buffer', 'features'),     # the window buffer; the feature sets
    ('learning', 'storage'),    # model, training, online learning, drift, envelope; window files, bags, writer
    ('triggers', 'sim'),        # the trigger kinds; the simulated robot (writes its bags through storage)
    ('logger',),                # the smart logger, collect mode, events, configuration, options
    ('nodes', 'offline'),       # the ROS edge; cclog, replay, fleet
)
ROOT = 'cc_log'  # the package's own __init__ (its version): under every floor, it imports nothing of cc_log


def floor_of():
    """package name -> index of its floor in FLOORS."""
    return {package: index for index, packages in enumerate(FLOORS) for package in packages}


def package_of(module):
    """``cc_log.storage.bag.bagio`` -> ``storage``; the root package ``cc_log`` -> ROOT."""
    parts = module.split('.')
    return parts[1] if len(parts) > 1 else ROOT


def imports_against_floors(graph, floors):
    """The imports ``(module, imported)`` of ``graph`` (module -> modules it imports) that go up or sideways:
    to a package on a higher floor, or to another package on the same floor. The root imports nothing; anyone
    may import the root."""
    wrong = []
    for module, imported in sorted(graph.items()):
        package = package_of(module)
        for target in sorted(imported):
            other = package_of(target)
            if other == package or other == ROOT:
                continue
            if package == ROOT or floors[other] >= floors[package]:
                wrong.append((module, target))
    return wrong


def test_imports_against_floors_are_found():
    floors = {'low': 0, 'mid': 1, 'side': 1, 'top': 2}
    graph = {'cc_log.mid.a': {'cc_log.low.b', 'cc_log.mid.c', 'cc_log'},
             'cc_log.low.b': {'cc_log.top.d'},          # up
             'cc_log.mid.c': {'cc_log.side.e'},         # sideways
             'cc_log.top.d': {'cc_log.mid.a', 'cc_log.low.b'},
             'cc_log': {'cc_log.low.b'}}                # the root imports nothing
    assert imports_against_floors(graph, floors) == [
        ('cc_log', 'cc_log.low.b'), ('cc_log.low.b', 'cc_log.top.d'), ('cc_log.mid.c', 'cc_log.side.e')]


def test_the_folders_are_the_floors():
    folders = {name for name in os.listdir(PACKAGE) if os.path.isfile(os.path.join(PACKAGE, name, '__init__.py'))}
    placed = set(floor_of())
    assert sum(len(packages) for packages in FLOORS) == len(placed), 'a package on two floors'
    assert folders == placed, 'folders not on a floor: %s; floors without a folder: %s' % (
        sorted(folders - placed), sorted(placed - folders))
    modules = {name for name in os.listdir(PACKAGE) if name.endswith('.py') and name != '__init__.py'}
    assert not modules, 'modules beside the packages, on no floor: %s' % sorted(modules)


def test_each_package_imports_only_from_the_floors_below():
    modules = cc_log_modules()
    graph = {name: imported_modules(path, modules) - {name} for name, path in modules.items()}
    floors = floor_of()
    unplaced = sorted({package_of(name) for name in graph} - set(floors) - {ROOT})
    assert not unplaced, 'packages on no floor (add them to FLOORS): %s' % unplaced
    wrong = imports_against_floors(graph, floors)
    assert not wrong, 'imports up or sideways (FLOORS, from the ground up: %s):\n%s' % (
        ' < '.join('/'.join(packages) for packages in FLOORS),
        '\n'.join('%s (%s) imports %s (%s)' % (module, package_of(module), target, package_of(target))
                  for module, target in wrong))

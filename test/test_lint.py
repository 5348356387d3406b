"""Lint is part of the test run: flake8 (the project's .flake8) and catkin_lint -W2 report nothing."""
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def run(args, cwd):
    return subprocess.run(args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True,
                          timeout=300)


def test_flake8_reports_nothing():
    result = run([sys.executable, '-m', 'flake8'], ROOT)
    assert result.returncode == 0 and result.stdout.strip() == '', 'flake8 (.flake8):\n' + result.stdout


def test_catkin_lint_reports_nothing(tmp_path):
    catkin_lint = shutil.which('catkin_lint')
    assert catkin_lint, 'catkin_lint is not installed (Debian package catkin-lint, rosdep key python3-catkin-lint)'
    package = tmp_path / 'cc_log'  # catkin_lint wants the directory named as the package
    package.symlink_to(ROOT)
    result = run([catkin_lint, '-W2', '--quiet', str(package)], str(tmp_path))
    problems = [line for line in result.stdout.splitlines() if line.startswith('cc_log:')]
    assert result.returncode == 0 and not problems, 'catkin_lint -W2:\n' + result.stdout


# -- the module graph of src/cc_log ---------------------------------------------------------------------------

PACKAGE = os.path.join(ROOT, 'src', 'cc_log')
MAX_MODULE_LINES = 600


def cc_log_modules():
    """dotted module name -> path of every module of src/cc_log."""
    modules = {}
    for folder, _, files in os.walk(PACKAGE):
        for name in files:
            if name.endswith('.py'):
                path = os.path.join(folder, name)
                dotted = os.path.relpath(path, os.path.dirname(PACKAGE))[:-3].replace(os.sep, '.')
                modules[dotted[:-len('.__init__')] if dotted.endswith('.__init__') else dotted] = path
    return modules


def imported_modules(path, modules):
    """The cc_log modules a module imports, anywhere in it (inside functions too): ``from a.b import c`` is the
    module a.b.c when there is one, else a.b; a relative import is resolved from the module's package."""
    import ast
    with open(path) as source:
        tree = ast.parse(source.read(), path)
    package = os.path.relpath(os.path.dirname(path), os.path.dirname(PACKAGE)).split(os.sep)
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            start = '.'.join(package[:len(package) - node.level + 1] + [node.module or ''] if node.level else
                             [node.module]).strip('.')
            names = [start + '.' + alias.name if start + '.' + alias.name in modules else start
                     for alias in node.names]
        else:
            continue
        for name in names:
            while name and name not in modules:
                name = name.rpartition('.')[0]
            if name:
                found.add(name)
    return found


def import_cycles(graph):
    """The strongly connected components of more than one module (or a module importing itself), sorted."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, edges = work[-1]
            for target in edges:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph[target]))))
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1 or node in graph[node]:
                        cycles.append(sorted(component))
    return sorted(cycles)


def test_import_cycles_are_found():
    assert import_cycles({'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}) == [['a', 'b', 'c']]
    assert import_cycles({'a': {'b'}, 'b': set()}) == []


def test_no_import_cycle_among_cc_log_modules():
    modules = cc_log_modules()
    graph = {name: imported_modules(path, modules) - {name} for name, path in modules.items()}
    cycles = import_cycles(graph)
    assert not cycles, 'import cycles (counting imports inside functions):\n' + '\n'.join(
        ', '.join('%s -> %s' % (name, sorted(graph[name] & set(cycle))) for name in cycle) for cycle in cycles)


def test_no_module_in_src_cc_log_over_600_lines():
    over = {}
    for path in cc_log_modules().values():
        with open(path) as source:
            lines = sum(1 for _ in source)
        if lines > MAX_MODULE_LINES:
            over[os.path.relpath(path, PACKAGE)] = lines
    assert not over, 'over %d lines: %s' % (MAX_MODULE_LINES, over)

"""bench/ a reader can navigate (issue 44): bench/README.md maps each question to one command and names every file
of bench/; docs/RESULTS.md stays a summary (at most 300 lines) whose every command is there to re-make it."""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, 'bench')
MAX_RESULTS_LINES = 300
QUESTIONS = ('How well does it detect?', 'What does it cost live?', 'What does it cost offline?',
             'How much does it store?', 'Heavy sensors', 'A fleet of robots?')


def text(*path):
    with open(os.path.join(ROOT, *path)) as stream:
        return stream.read()


def test_results_is_a_summary_of_at_most_300_lines():
    lines = text('docs', 'RESULTS.md').count('\n')
    assert lines <= MAX_RESULTS_LINES, 'docs/RESULTS.md: %d lines' % lines


def test_the_readme_names_every_file_of_bench():
    readme = text('bench', 'README.md')
    named = set(re.findall(r'`(?:python3 )?(?:bench/)?([\w.]+\.(?:py|sh))', readme))
    files = set(name for name in os.listdir(BENCH) if name.endswith(('.py', '.sh')))
    assert files - named == set()  # every file is listed
    assert named - files == set()  # and every file listed is there


def test_each_question_has_one_command():
    section = text('bench', 'README.md').split('## The questions', 1)[1].split('\n## ', 1)[0]
    rows = [line for line in section.splitlines() if line.startswith('| ')]
    assert len(rows) == 1 + len(QUESTIONS)  # the header and one row a question
    for question in QUESTIONS:
        commands = [re.findall(r'`python3 (bench/[\w.]+)', row) for row in rows if row.startswith('| ' + question)]
        assert len(commands) == 1 and len(commands[0]) == 1, (question, commands)
        assert os.path.isfile(os.path.join(ROOT, commands[0][0])), commands


def test_every_detection_part_is_a_bench_module_and_in_the_readme():
    sys.path.insert(0, BENCH)
    try:
        import detection
    finally:
        sys.path.remove(BENCH)
    readme = text('bench', 'README.md')
    for part, (module, _) in detection.PARTS.items():
        assert os.path.isfile(os.path.join(BENCH, module + '.py')), module
        assert '| `%s` | `%s.py` |' % (part, module) in readme, part
    assert detection.main(['no_such_part']) == 2


def test_every_command_the_results_cite_is_there_with_its_flags():
    for page in ('RESULTS.md', 'DETECTION.md'):
        for script, flag in re.findall(r'bench/(\w+\.py)((?: --[\w-]+)?)', text('docs', page)):
            assert os.path.isfile(os.path.join(BENCH, script)), (page, script)
            if flag:  # a flag the figure was made with is still one the command takes
                assert flag.strip() in text('bench', script), (page, script, flag)

"""Runs the Python tests for tests/check_python.c and records each result.

usage: runner.py RESULTS

Discovers tests/python/test_*.py, writes one line per test id ("ID\t<id>")
and then, as each test ends, "PASS\t<id>", "SKIP\t<id>\t<reason>" or
"FAIL\t<id>\t<message>" (newlines escaped as \\n), flushed, so that a test
run that dies part way still says which tests ran. The check suite turns the
lines into Check results (a skip prints "SKIP: "). Other output (tracebacks,
progress) goes to stdout/stderr, which the suite keeps in a log.

The same tests run on their own with unittest:
    PYTHONPATH=python:tests/python HEATVOX_LIBRARY=build/libheatvox.so \\
        /usr/bin/python3 -m unittest discover -s tests/python
"""

import os
import sys
import unittest

here = os.path.dirname(os.path.abspath(__file__))


def escape(s):
    return s.replace("\\", "\\\\").replace("\t", "\\t").replace("\n", "\\n")


def flatten(suite):
    for t in suite:
        if isinstance(t, unittest.TestSuite):
            yield from flatten(t)
        else:
            yield t


class Recorder(unittest.TextTestResult):
    def __init__(self, out, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.out = out
        self.failed_ids = set()

    def _line(self, *fields):
        self.out.write("\t".join(escape(str(f)) for f in fields) + "\n")
        self.out.flush()

    def addSuccess(self, test):
        super().addSuccess(test)
        self._line("PASS", test.id())

    def addSkip(self, test, reason):
        super().addSkip(test, reason)
        self._line("SKIP", test.id(), reason)

    def addFailure(self, test, err):
        super().addFailure(test, err)
        self._line("FAIL", test.id(), self.failures[-1][1])

    def addError(self, test, err):
        super().addError(test, err)
        # setUpClass errors come with a _ErrorHolder "test": fail every test of it
        self._line("FAIL", test.id(), self.errors[-1][1])

    def addExpectedFailure(self, test, err):
        super().addExpectedFailure(test, err)
        self._line("PASS", test.id())

    def addUnexpectedSuccess(self, test):
        super().addUnexpectedSuccess(test)
        self._line("FAIL", test.id(), "unexpected success")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    suite = unittest.defaultTestLoader.discover(here, pattern="test_*.py", top_level_dir=here)
    tests = list(flatten(suite))
    with open(sys.argv[1], "w") as out:
        for t in tests:
            out.write("ID\t%s\n" % escape(t.id()))
        out.flush()
        runner = unittest.TextTestRunner(
            stream=sys.stderr, verbosity=2, resultclass=lambda *a, **k: Recorder(out, *a, **k)
        )
        result = runner.run(suite)
    sys.exit(0 if result.wasSuccessful() else 1)


if __name__ == "__main__":
    main()

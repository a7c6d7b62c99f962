"""README.md's Python example runs as written, from a directory laid out like
the repository root (scenes/ from make-scenes, out/)."""

import os
import re
import subprocess
import sys
import unittest

import hvtest


def readme_example():
    with open(os.path.join(hvtest.REPO, "README.md")) as f:
        text = f.read()
    section = text.split("\n## Python\n", 1)
    if len(section) != 2:
        raise AssertionError("README.md has no '## Python' section")
    m = re.search(r"\n```python\n(.*?)\n```\n", section[1], re.S)
    if not m:
        raise AssertionError("the Python section of README.md has no ```python block")
    return m.group(1) + "\n"


class Readme(unittest.TestCase):
    def test_the_python_example_should_run_as_written(self):
        code = readme_example()
        self.assertLessEqual(len(code.strip().split("\n")), 5, "keep the example at five lines")
        d = hvtest.tmpdir()
        os.symlink(hvtest.scenes(), os.path.join(d, "scenes"))
        os.mkdir(os.path.join(d, "out"))
        with open(os.path.join(d, "example.py"), "w") as f:
            f.write(code)
        # the same interpreter and environment (PYTHONPATH, HEATVOX_LIBRARY) as this test
        p = subprocess.run([sys.executable, "example.py"], cwd=d, env=hvtest.child_env(), capture_output=True,
                           text=True, timeout=120)
        self.assertEqual(p.returncode, 0, "README example failed:\n%s%s" % (p.stdout, p.stderr))
        self.assertTrue(os.path.getsize(os.path.join(d, "out", "sphere_py.vdb")) > 0)
        self.assertRegex(p.stdout, r"^\(\d+, \d+, \d+\) ")


if __name__ == "__main__":
    unittest.main()

"""The ctypes structs mirror the C headers: sizes and every field's offset,
as a C compiler lays them out (a program compiled here, not in the package)."""

import os
import shutil
import subprocess
import unittest

import hvtest
from heatvox import _lib


def c_name(field):
    return "in" if field == "in_" else field


class Layout(unittest.TestCase):
    def test_every_struct_should_have_the_c_size_and_offsets(self):
        cc = shutil.which("cc") or shutil.which("gcc")
        if not cc:
            self.skipTest("no C compiler (cc) to compare the struct layouts with")
        d = hvtest.tmpdir()
        lines, expect = [], []
        for s in _lib.STRUCTS:
            name = s.__name__
            lines.append('printf("%s %%zu\\n", sizeof(%s));' % (name, name))
            expect.append("%s %d" % (name, _lib.ctypes.sizeof(s)))
            for field, _ in s._fields_:
                lines.append('printf("%s.%s %%zu\\n", offsetof(%s, %s));' % (name, c_name(field), name, c_name(field)))
                expect.append("%s.%s %d" % (name, c_name(field), getattr(s, field).offset))
        src = os.path.join(d, "layout.c")
        with open(src, "w") as f:
            f.write("#include <heatvox/heatvox.h>\n#include <stddef.h>\n#include <stdio.h>\n")
            f.write("int main(void)\n{\n    " + "\n    ".join(lines) + "\n    return 0;\n}\n")
        exe = os.path.join(d, "layout")
        p = subprocess.run([cc, "-std=c11", "-I", os.path.join(hvtest.REPO, "include"), src, "-o", exe],
                           capture_output=True, text=True)
        self.assertEqual(p.returncode, 0, p.stderr)
        got = subprocess.run([exe], capture_output=True, text=True, check=True).stdout.split("\n")[:-1]
        self.assertEqual(got, expect)
        self.assertEqual(len(_lib.STRUCTS), 20)


if __name__ == "__main__":
    unittest.main()

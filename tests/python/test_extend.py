"""heatvox.extend and Extender against `heatvox extend` on the generated
level set with a velocity (read by pyopenvdb), bit for bit; field forms,
reuse, 2D, errors."""

import os
import unittest

import numpy as np

import heatvox
import hvtest


def read_block(path, name, vec=False):
    """A grid of heatvox's block as (nz, ny, nx) (vectors: a tuple of 3), and h."""
    vdb = hvtest.need_pyopenvdb()
    g = vdb.read(path, name)
    lo, hi = g.metadata["heatvox_block_min"], g.metadata["heatvox_block_max"]
    n = tuple(hi[a] - lo[a] + 1 for a in range(3))
    arr = np.zeros(n + ((3,) if vec else ()), np.float32)  # [i, j, k(, c)]
    g.copyToArray(arr, ijk=lo)
    h = g.transform.voxelSize()[0]
    if vec:
        return tuple(np.ascontiguousarray(arr[..., c].transpose(2, 1, 0)) for c in range(3)), h
    return np.ascontiguousarray(arr.transpose(2, 1, 0)), h


class SameAsCommand(unittest.TestCase):
    def test_vector_extension_should_equal_the_command(self):
        src = hvtest.scene("levelset/sphere_velocity.vdb")
        out = os.path.join(hvtest.tmpdir(), "ext.vdb")
        hvtest.run("extend", src, "--levelset", "sdf", "--field", "v", "-o", out, "-q", "--dense")
        phi, h = read_block(src, "sdf")
        v, _ = read_block(src, "v", vec=True)
        ref, _ = read_block(out, "v", vec=True)
        phi_back, _ = read_block(out, "sdf")
        hvtest.assert_bits_equal(self, phi_back, phi, "the level set as the command read it")
        mine = heatvox.extend(phi, v, h)
        self.assertIsInstance(mine, tuple)
        for c in range(3):
            hvtest.assert_bits_equal(self, mine[c], ref[c], "component %d" % c)
        # the (3, nz, ny, nx) form gives the same
        stacked = heatvox.extend(phi, np.stack(v), h)
        self.assertEqual(stacked.shape, (3,) + phi.shape)
        for c in range(3):
            hvtest.assert_bits_equal(self, stacked[c], ref[c], "stacked component %d" % c)

    def test_options_should_equal_the_command(self):
        src = hvtest.scene("levelset/sphere_velocity.vdb")
        out = os.path.join(hvtest.tmpdir(), "ext.vdb")
        hvtest.run("extend", src, "--levelset", "sdf", "--field", "v", "-o", out, "-q", "--dense",
                   "--band", "2", "--out-band", "4", "--t-scale", "0.5", "--plain")
        phi, h = read_block(src, "sdf")
        v, _ = read_block(src, "v", vec=True)
        ref, _ = read_block(out, "v", vec=True)
        mine = heatvox.extend(phi, v, h, band=2, out_band=4, t_scale=0.5, closest_point=False)
        for c in range(3):
            hvtest.assert_bits_equal(self, mine[c], ref[c], "component %d" % c)


def sphere(n=32, r=0.3):
    h = 1.0 / n
    z, y, x = np.meshgrid(*[(np.arange(n) + 0.5) * h - 0.5] * 3, indexing="ij")
    phi = (np.sqrt(x * x + y * y + z * z) - r).astype(np.float32)
    return phi, h, (x, y, z)


class Extension(unittest.TestCase):
    def test_a_surface_function_should_become_constant_along_normals(self):
        phi, h, (x, y, z) = sphere()
        f = (z / np.sqrt(x * x + y * y + z * z)).astype(np.float32)  # cos(polar angle)
        e = heatvox.extend(phi, f * (1 + phi), h)  # wrong off the surface on purpose
        far = np.abs(phi) < 6 * h
        self.assertLess(np.abs(e - f)[far].mean(), 0.02)
        const = heatvox.extend(phi, np.full_like(phi, 2.5), h)
        self.assertTrue(np.allclose(const, 2.5, rtol=1e-6))

    def test_extender_should_be_reusable_and_write_in_place(self):
        phi, h, (x, y, z) = sphere()
        f = x.astype(np.float32)
        with heatvox.Extender(phi.shape, h) as ex:
            a = ex.extend(phi, f)
            b = ex.extend(phi, f)
            hvtest.assert_bits_equal(self, a, b, "second call")
            self.assertGreater(ex.stats["source_cells"], 0)
            g = f.copy()
            r = ex.extend(phi, g, out=g)  # out may alias in
            self.assertIs(r, g)
            hvtest.assert_bits_equal(self, g, a, "in place")
            both = ex.extend(phi, [f, (f, y.astype(np.float32), z.astype(np.float32))])
            self.assertIsInstance(both, list)
            self.assertTrue(np.allclose(both[0], a, atol=1e-6))
            self.assertEqual(len(both[1]), 3)

    def test_a_grid_should_be_accepted_as_phi(self):
        g = heatvox.sdf(hvtest.scene("meshes/sphere_holes_flips.obj"), res=24)
        f = np.ones(g.shape, np.float32)
        e = heatvox.extend(g, f)
        self.assertTrue(np.allclose(e, 1.0, rtol=1e-6))

    def test_2d_should_extend_off_a_circle(self):
        n, h = 64, 1.0 / 64
        y, x = np.meshgrid(*[(np.arange(n) + 0.5) * h - 0.5] * 2, indexing="ij")
        phi = (np.hypot(x, y) - 0.25).astype(np.float32)
        f = (x / np.hypot(x, y)).astype(np.float32)
        e = heatvox.extend(phi, f, h)
        self.assertEqual(e.shape, (n, n))
        near = np.abs(phi) < 8 * h
        self.assertLess(np.abs(e - f)[near].mean(), 0.02)

    def test_progress_should_be_called_and_cancel(self):
        phi, h, (x, y, z) = sphere(16)
        seen = []
        heatvox.extend(phi, x.astype(np.float32), h, progress=lambda f, s: seen.append(s))
        self.assertIn("extend", seen)
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.extend(phi, x.astype(np.float32), h, progress=lambda f, s: True)
        self.assertEqual(cm.exception.status, heatvox.Status.CANCELLED)

    def test_errors(self):
        phi, h, _ = sphere(16)
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.extend(phi + 10, np.zeros_like(phi), h)  # no zero crossing
        self.assertEqual(cm.exception.status, heatvox.Status.INVALID_ARG)
        self.assertIn("band", cm.exception.message)
        with self.assertRaises(ValueError):
            heatvox.extend(phi, np.zeros((16, 16, 15), np.float32), h)
        with self.assertRaises(ValueError):
            heatvox.extend(phi, (phi, phi, phi, phi), h)
        with self.assertRaises(ValueError):
            heatvox.extend(phi, phi, h, band=0)
        with self.assertRaises(TypeError):
            heatvox.extend(phi, phi)
        with self.assertRaises(TypeError):
            heatvox.extend(phi, phi, h, no_such_option=1)
        with self.assertRaises(ValueError):
            heatvox.Extender(phi.shape, h).extend(phi, phi, out=np.zeros((16, 16, 16)))  # float64 out


if __name__ == "__main__":
    unittest.main()

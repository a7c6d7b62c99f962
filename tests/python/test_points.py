"""Oriented point clouds from Python: read_points, points_surface, and
sdf(path) on a cloud against `heatvox sdf --npy`, bit for bit."""

import os
import unittest

import numpy as np

import heatvox
import hvtest


def sphere_cloud(n=6000, seed=3):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    return p * 0.8, p.copy()


def write_xyz(points, normals):
    path = os.path.join(hvtest.tmpdir(), "cloud.xyz")
    np.savetxt(path, np.hstack([points, normals]), fmt="%.17g", header="x y z nx ny nz")
    return path


class Points(unittest.TestCase):
    def test_read_points_should_give_the_file_and_unit_normals(self):
        p, n = sphere_cloud()
        path = write_xyz(p, 2 * n)
        q, m = heatvox.read_points(path)
        self.assertEqual(q.shape, (6000, 3))
        np.testing.assert_array_equal(q, p)
        np.testing.assert_allclose(m, n, atol=1e-15)

    def test_unoriented_cloud_should_read_without_normals(self):
        path = os.path.join(hvtest.tmpdir(), "bare.xyz")
        with open(path, "w") as f:
            f.write("# no normals\n0 0 0\n1 2 3\n")
        q, m = heatvox.read_points(path)
        self.assertIsNone(m)
        np.testing.assert_array_equal(q, [[0, 0, 0], [1, 2, 3]])

    def test_mixed_cloud_should_raise_naming_file_and_line(self):
        path = os.path.join(hvtest.tmpdir(), "mixed.xyz")
        with open(path, "w") as f:
            f.write("# no normals\n0 0 0\n1 2 3 0 0 1\n")
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.read_points(path)
        self.assertIn(path + ": line 3", str(cm.exception))
        self.assertIn("where the points before have none", str(cm.exception))

    def test_points_surface_without_normals_should_be_the_sphere(self):
        p, _ = sphere_cloud()
        v, f, rep = heatvox.points_surface(p, None, res=48)
        self.assertEqual(rep["recovered"], 1)
        r = np.linalg.norm(v, axis=1)
        self.assertLess(np.abs(r - 0.8).max(), 0.5 * rep["h"])
        # outward: the signed volume of the closed surface is the ball's
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        vol = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
        self.assertAlmostEqual(vol, 4 / 3 * np.pi * 0.8 ** 3, delta=0.03)
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.points_surface(p, None, res=48, orient="given")
        self.assertIn("no normals", str(cm.exception))
        with self.assertRaises(ValueError):
            heatvox.points_surface(p, None, res=48, orient="sideways")

    def test_points_surface_should_be_the_sphere(self):
        p, n = sphere_cloud()
        n[::10] *= -1  # a tenth of the normals turned around
        v, f, rep = heatvox.points_surface(p, n, res=48)
        self.assertEqual(f.shape[1], 3)
        r = np.linalg.norm(v, axis=1)
        h = rep["h"]
        self.assertLess(np.abs(r - 0.8).mean() / h, 0.05)
        self.assertEqual(rep["points"], 6000)
        self.assertEqual(rep["normals_against"], 600)
        g = heatvox.sdf(v, f, res=48)
        self.assertLess(g.values.min(), -0.7)

    def test_sdf_of_a_cloud_path_should_equal_command_npy(self):
        path = write_xyz(*sphere_cloud())
        d = hvtest.tmpdir()
        npy = os.path.join(d, "c.npy")
        hvtest.run("sdf", path, "--npy", npy, "--res", "40", "-q")
        g = heatvox.sdf(path, res=40)
        hvtest.assert_bits_equal(self, g.values, np.load(npy), "cloud")

    def test_bad_arrays_should_raise_before_calling_c(self):
        p, n = sphere_cloud(10)
        with self.assertRaises(ValueError):
            heatvox.points_surface(p, n[:5])
        with self.assertRaises(ValueError):
            heatvox.points_surface(p[:, :2], n[:, :2])


if __name__ == "__main__":
    unittest.main()

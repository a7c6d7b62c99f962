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


def _box_faces(lo, hi, n, rng):
    """n points uniform on the faces of the box lo..hi, with outward normals."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ext = hi - lo
    areas = np.array([ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[1]]).repeat(2)
    face = rng.choice(6, n, p=areas / areas.sum())
    x = lo + rng.random((n, 3)) * ext
    nrm = np.zeros((n, 3))
    for k in range(6):
        a, m = k // 2, face == k
        x[m, a] = lo[a] if k % 2 == 0 else hi[a]
        nrm[m, a] = -1 if k % 2 == 0 else 1
    return x, nrm


def _cup(res, wall, n, rng):
    """n points on a cup (outer radius 0.8, walls and bottom `wall` voxels
    thick at res, an open rim), with outward normals."""
    h = 2.0 / (res - 8)
    w, R, H, z0 = wall * h, 0.8, 1.6, -0.8
    Ri = R - w

    def side(r, zlo, zhi, m, sign):
        th, z = rng.random(m) * 2 * np.pi, zlo + rng.random(m) * (zhi - zlo)
        return np.c_[r * np.cos(th), r * np.sin(th), z], sign * np.c_[np.cos(th), np.sin(th), 0 * z]

    def ring(r0, r1, z, m, sign):
        th, r = rng.random(m) * 2 * np.pi, np.sqrt(r0 ** 2 + rng.random(m) * (r1 ** 2 - r0 ** 2))
        nrm = np.zeros((m, 3))
        nrm[:, 2] = sign
        return np.c_[r * np.cos(th), r * np.sin(th), np.full(m, z)], nrm

    areas = np.array([2 * np.pi * R * H, 2 * np.pi * Ri * (H - w), np.pi * R * R, np.pi * Ri * Ri,
                      np.pi * (R * R - Ri * Ri)])
    c = np.round(areas / areas.sum() * n).astype(int)
    parts = [side(R, z0, z0 + H, c[0], 1), side(Ri, z0 + w, z0 + H, c[1], -1), ring(0, R, z0, c[2], -1),
             ring(0, Ri, z0 + w, c[3], 1), ring(Ri, R, z0 + H, c[4], 1)]
    return np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])


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

    def test_thin_walls_should_get_opposite_normals_on_their_faces(self):
        # a plate 1.5 voxels thick and a cup with walls of 2 voxels at 96^3,
        # points on both faces: the recovered normals (turned to agree with
        # the signed field) on their true side for at least 99% of them
        rng = np.random.default_rng(5)
        h = 2.0 / 88
        for name, (p, n) in (("plate", _box_faces([-1, -1, -0.75 * h], [1, 1, 0.75 * h], 60000, rng)),
                             ("cup", _cup(96, 2.0, 60000, rng))):
            _, _, rep = heatvox.points_surface(p, n, res=96, orient="recover")
            agree = 1 - rep["orient_disagree"] / len(p)
            self.assertGreaterEqual(agree, 0.99, "%s: %.4f on their true side" % (name, agree))

    def test_points_surface_without_normals_should_be_the_sphere(self):
        p, _ = sphere_cloud()
        v, f, rep = heatvox.points_surface(p, None, res=48)
        self.assertEqual(rep["recovered"], 1)
        # clean: the neighbourhoods' own axes, not the diffused line field
        self.assertLess(rep["orient_spread"], 0.05)
        self.assertEqual(rep["orient_lines"], 0)
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

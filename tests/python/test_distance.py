"""heatvox.distance against `heatvox distance --npy` for the same grid and
sources, bit for bit; source forms; the solid mask used in place; errors."""

import os
import unittest

import numpy as np

import heatvox
import hvtest


def command_npy(*opts):
    d = hvtest.tmpdir()
    npy = os.path.join(d, "d.npy")
    hvtest.run("distance", "--npy", npy, "-q", *opts)
    return np.load(npy)


def sources_file(lines):
    p = os.path.join(hvtest.tmpdir(), "src.txt")
    with open(p, "w") as f:
        f.write("\n".join(lines) + "\n")
    return p


class SameAsCommand(unittest.TestCase):
    def test_point_source_in_free_space_should_equal_command_npy(self):
        # --bbox 0 0 0 4 3 1 with --res 32: h = 1/8, 32 x 24 x 8 cells from 0
        ref = command_npy("--sources", hvtest.scene("distance/sources.txt"), "--obstacles", "none",
                          "--bbox", "0", "0", "0", "4", "3", "1", "--res", "32")
        g = heatvox.distance(np.array([[0.5, 1.5, 0.5]]), None, 0.125, shape=(8, 24, 32))
        hvtest.assert_bits_equal(self, g.values, ref, "distance")
        self.assertEqual(g.name, "distance")
        self.assertFalse(g.levelset)
        # free space: nearly the Euclidean distance
        z, y, x = np.meshgrid(*[(np.arange(n) + 0.5) * 0.125 for n in (8, 24, 32)], indexing="ij")
        exact = np.sqrt((x - 0.5) ** 2 + (y - 1.5) ** 2 + (z - 0.5) ** 2)
        self.assertLess(np.abs(g.values - exact).mean(), 0.125)

    def test_obstacle_mesh_should_equal_command_npy(self):
        bbox = ["-0.5", "-0.5", "-0.5", "4.5", "3.5", "1.5"]  # h = 5/40 = 1/8: 40 x 32 x 16
        building = hvtest.scene("distance/building.obj")
        ref = command_npy("--sources", hvtest.scene("distance/sources.txt"), "--obstacle-mesh", building,
                          "--bbox", *bbox, "--res", "40")
        shape, h, origin = (16, 32, 40), 0.125, (-0.5, -0.5, -0.5)
        solid = heatvox.mask_from_mesh(*heatvox.read_mesh(building), shape, h, origin)
        self.assertEqual(solid.dtype, np.bool_)
        self.assertGreater(int(solid.sum()), 0)
        g = heatvox.distance(np.array([[0.5, 1.5, 0.5]]), solid, h, origin=origin)
        hvtest.assert_bits_equal(self, g.values, ref, "distance")
        self.assertTrue(np.all(np.isinf(g.values[solid])))
        self.assertGreater(g.stats["unreachable_cells"], 0)  # the sealed closet
        self.assertEqual(g.stats["regions"], 1)
        # the mask is used in place, not copied
        self.assertTrue(np.shares_memory(g.solid, solid))

    def test_2d_should_equal_command_npy(self):
        ref = command_npy("--sources", hvtest.scene("distance/sources_2d.txt"), "--dim", "2",
                          "--bbox", "0", "0", "4", "3", "--res", "32")
        g = heatvox.distance(np.array([[0.5, 1.5]]), None, 0.125, shape=(24, 32))
        self.assertEqual(g.dim, 2)
        hvtest.assert_bits_equal(self, g.values, ref, "distance")

    def test_voxel_sources_should_equal_command_voxel_records(self):
        ref = command_npy("--sources", sources_file(["voxel 3 4 2", "voxel 20 10 5"]), "--obstacles", "none",
                          "--bbox", "0", "0", "0", "4", "3", "1", "--res", "32", "--unreachable", "-1")
        shape = (8, 24, 32)
        cells = np.zeros(shape, bool)
        cells[2, 4, 3] = cells[5, 10, 20] = True
        a = heatvox.distance(cells, None, 0.125, unreachable=-1)
        b = heatvox.distance(np.array([[3, 4, 2], [20, 10, 5]]), None, 0.125, shape=shape, unreachable=-1)
        hvtest.assert_bits_equal(self, a.values, ref, "bool sources")
        hvtest.assert_bits_equal(self, b.values, ref, "index sources")
        self.assertEqual(a.values[2, 4, 3], 0.0)


class ManyQueries(unittest.TestCase):
    """heatvox.Distance: one set-up for many source sets; the command's
    several --sources, one grid each in the VDB, read back by pyopenvdb."""

    def setUp(self):
        self.building = hvtest.scene("distance/building.obj")
        self.shape, self.h, self.origin = (16, 32, 40), 0.125, (-0.5, -0.5, -0.5)
        self.bbox = ["-0.5", "-0.5", "-0.5", "4.5", "3.5", "1.5"]
        self.solid = heatvox.mask_from_mesh(*heatvox.read_mesh(self.building), self.shape, self.h,
                                            self.origin)

    def test_queries_should_equal_single_calls_and_pay_set_up_once(self):
        pts = [np.array([[0.5, 1.5, 0.5]]), np.array([[3.5, 0.5, 0.5]])]
        with heatvox.Distance(self.solid, self.h, origin=self.origin) as d:
            got = [d.query(p) for p in pts]
            again = d.query(pts[0])
        for p, g in zip(pts, got):
            one = heatvox.distance(p, self.solid, self.h, origin=self.origin)
            hvtest.assert_bits_equal(self, g.values, one.values, "query")
        hvtest.assert_bits_equal(self, again.values, got[0].values, "the same query again")
        self.assertGreater(got[0].stats["t_setup"], 0)
        self.assertEqual(got[1].stats["t_setup"], 0)
        self.assertGreater(got[0].stats["cells_solved"], 0)
        with self.assertRaises(ValueError):
            d.query(pts[0])

    def test_several_source_sets_should_write_one_grid_each(self):
        vdb = hvtest.need_pyopenvdb()
        a = hvtest.scene("distance/sources.txt")
        b = sources_file(["3.5 0.5 0.5"])
        opts = ["--obstacle-mesh", self.building, "--bbox", *self.bbox, "--res", "40"]
        out = os.path.join(hvtest.tmpdir(), "two.vdb")
        hvtest.run("distance", "--sources", a, "--sources", b, "-o", out, "-q", *opts)
        names = sorted(g.name for g in vdb.readAllGridMetadata(out))
        self.assertEqual(names, ["distance", "distance_2", "obstacles"])
        for name, src in (("distance", a), ("distance_2", b)):
            ref = command_npy("--sources", src, *opts)
            grid = vdb.read(out, name)
            got = np.zeros(ref.shape[::-1], np.float32)
            grid.copyToArray(got, ijk=(0, 0, 0))
            hvtest.assert_bits_equal(self, got.transpose(2, 1, 0), ref, name)
        hvtest.run("distance", "--sources", a, "--sources", b, "-o", out, "--npy",
                   os.path.join(hvtest.tmpdir(), "x.npy"), *opts, expect=2)


class Arguments(unittest.TestCase):
    def test_progress_should_be_called_and_cancel(self):
        seen = []
        heatvox.distance(np.array([[1.0, 1.0]]), None, 0.1, shape=(20, 20), progress=lambda f, s: seen.append(s))
        self.assertIn("diffuse", seen)
        self.assertIn("poisson", seen)
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.distance(np.array([[1.0, 1.0]]), None, 0.1, shape=(20, 20), progress=lambda f, s: s == "poisson")
        self.assertEqual(cm.exception.status, heatvox.Status.CANCELLED)

    def test_sources_only_in_solid_should_raise_error(self):
        solid = np.ones((8, 8), bool)
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.distance(np.array([[4, 4]]), solid, 1.0)
        self.assertEqual(cm.exception.status, heatvox.Status.INVALID_ARG)
        self.assertIn("source", cm.exception.message)

    def test_bad_arguments_should_raise_before_calling_c(self):
        with self.assertRaises(ValueError):
            heatvox.distance(np.array([[0.5, 0.5, 0.5]]), None, 0.1)  # no shape
        with self.assertRaises(ValueError):
            heatvox.distance(None, None, 0.1, shape=(4, 4, 4))  # no sources
        with self.assertRaises(ValueError):
            heatvox.distance(np.zeros((4, 4), bool), None, 0.1, shape=(4, 4, 4))
        with self.assertRaises(ValueError):
            heatvox.distance(np.array([[9, 0, 0]]), None, 0.1, shape=(4, 4, 4))  # index out of range
        with self.assertRaises(ValueError):
            heatvox.distance(np.array([[0.5, 0.5, 0.5]]), np.zeros((4, 4, 5), bool), 0.1, shape=(4, 4, 4))
        with self.assertRaises(ValueError):
            heatvox.distance(np.array([[0.5, 0.5]]), None, 0.1, shape=(4, 4), mesh=heatvox.read_mesh(hvtest.scene("distance/building.obj")))
        with self.assertRaises(ValueError):
            heatvox.distance(np.array([[0.5, 0.5, 0.5]]), None, -1, shape=(4, 4, 4))
        with self.assertRaises(ValueError):
            heatvox.distance(np.array([[0.5, 0.5, 0.5]]), None, 1, shape=(4, 4, 4), backend="gpu")

    def test_mesh_sources_should_be_zero_on_the_surface(self):
        v, f = heatvox.read_mesh(hvtest.scene("meshes/sphere_holes_flips.obj"))
        g = heatvox.distance(None, None, 0.1, shape=(30, 30, 30), origin=(-1.5, -1.5, -1.5), mesh=(v, f))
        ijk = np.rint(g.world_to_index(v[::50])).astype(int)
        self.assertLess(float(g.values[ijk[:, 2], ijk[:, 1], ijk[:, 0]].max()), 0.15)
        self.assertGreater(float(g.values[0, 0, 0]), 1.0)


if __name__ == "__main__":
    unittest.main()

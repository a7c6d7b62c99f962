"""Grid: coordinates, .npy and .vdb output read back by independent readers
(NumPy, pyopenvdb), grids over your own arrays, isosurface meshes."""

import os
import unittest

import numpy as np

import heatvox
import hvtest


def read_vdb_dense(path, name, shape):
    """A grid of a .vdb file as a dense (nz, ny, nx) array over heatvox's
    block (heatvox_block_min), with its metadata, class and transform."""
    vdb = hvtest.need_pyopenvdb()
    g = vdb.read(path, name)
    lo = g.metadata["heatvox_block_min"]
    arr = np.zeros(tuple(reversed(shape)), dtype=np.float32)  # [i, j, k]
    g.copyToArray(arr, ijk=lo)
    return g, np.ascontiguousarray(arr.transpose(2, 1, 0))


class Coordinates(unittest.TestCase):
    def test_world_to_index_should_put_cell_centres_on_integers(self):
        g = heatvox.Grid(np.zeros((4, 5, 6), np.float32), 0.5, origin=(1.0, 2.0, 3.0))
        self.assertEqual(g.shape, (4, 5, 6))
        # sample (i, j, k) = (2, 3, 1) sits at origin + (i + 1/2) h
        p = np.array([1.0 + 2.5 * 0.5, 2.0 + 3.5 * 0.5, 3.0 + 1.5 * 0.5])
        self.assertTrue(np.allclose(g.world_to_index(p), [2, 3, 1]))
        self.assertTrue(np.allclose(g.world_to_index([1.0, 2.0, 3.0]), [-0.5, -0.5, -0.5]))
        pts = np.random.default_rng(1).uniform(-3, 3, (10, 3))
        self.assertTrue(np.allclose(g.index_to_world(g.world_to_index(pts)), pts))
        with self.assertRaises(ValueError):
            g.world_to_index(np.zeros((3, 2)))

    def test_world_to_index_should_agree_with_the_sdf(self):
        # the zero set of a sphere's distance sits at its radius: sample the
        # grid at the nearest cell to points 1.5 voxels outside the surface
        g = heatvox.sdf(hvtest.scene("meshes/sphere_holes_flips.obj"), res=48)
        d = np.random.default_rng(2).normal(size=(50, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        c = np.array(g.origin) + 0.5 * np.array(g.shape[::-1]) * g.voxel_size  # the block's centre
        ijk = np.rint(g.world_to_index(c + 1.05 * d)).astype(int)
        cell = g.index_to_world(ijk)
        vals = g.values[ijk[:, 2], ijk[:, 1], ijk[:, 0]]
        r = np.linalg.norm(cell - c, axis=1)
        self.assertLess(np.abs(vals - (r - 1.0)).max(), 0.3 * g.voxel_size)

    def test_2d_grids_should_use_x_y(self):
        g = heatvox.Grid(np.zeros((3, 4), np.float32), 1.0, origin=(0.0, 0.0))
        self.assertEqual(g.dim, 2)
        self.assertEqual(g.origin, (0.0, 0.0))
        self.assertTrue(np.allclose(g.world_to_index([[3.5, 2.5]]), [[3, 2]]))


class Output(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.mesh = hvtest.scene("meshes/sphere_holes_flips.obj")
        cls.grid = heatvox.sdf(cls.mesh, res=32, band=2.5)
        cls.dir = hvtest.tmpdir()

    def test_write_npy_should_read_back_with_numpy(self):
        p = os.path.join(self.dir, "g.npy")
        self.grid.write_npy(p)
        a = np.load(p)
        self.assertEqual(a.dtype, np.float32)
        self.assertTrue(hvtest.bits_equal(a, self.grid.values))

    def test_write_vdb_should_read_back_as_the_level_set(self):
        vdb = hvtest.need_pyopenvdb()
        p = os.path.join(self.dir, "g.vdb")
        self.grid.write_vdb(p)
        g, dense = read_vdb_dense(p, "sdf", self.grid.shape)
        h, band = self.grid.voxel_size, 2.5
        self.assertEqual(g.gridClass, vdb.GridClass.LEVEL_SET)
        self.assertAlmostEqual(g.background, band * h, places=6)
        self.assertTrue(np.allclose(g.transform.voxelSize(), [h] * 3))
        self.assertTrue(np.allclose(g.transform.indexToWorld(g.metadata["heatvox_block_min"]),
                                    np.array(self.grid.origin) + h / 2))
        v = self.grid.values
        active = np.abs(v) < band * h
        self.assertEqual(g.activeVoxelCount(), int(active.sum()))
        self.assertTrue(np.array_equal(dense[active], v[active]))
        # inactive voxels hold the background with the level set's sign
        self.assertTrue(np.all(np.abs(dense[~active]) == np.float32(band * h)))
        self.assertTrue(np.array_equal(np.sign(dense[~active]), np.sign(v[~active])))
        _, meta = vdb.readAll(p)
        self.assertEqual(meta["heatvox_version"], heatvox.__version__)

    def test_write_vdb_fog_should_read_back_as_the_inside(self):
        vdb = hvtest.need_pyopenvdb()
        p = os.path.join(self.dir, "fog.vdb")
        self.grid.write_vdb(p, fog="density")
        self.assertEqual(sorted(g.name for g in vdb.readAllGridMetadata(p)), ["density", "sdf"])
        g, dense = read_vdb_dense(p, "density", self.grid.shape)
        h = self.grid.voxel_size
        self.assertEqual(g.gridClass, vdb.GridClass.FOG_VOLUME)
        self.assertEqual(g.background, 0.0)
        self.assertTrue(np.allclose(g.transform.voxelSize(), [h] * 3))
        want = np.clip(0.5 - self.grid.values.astype(np.float64) / h, 0, 1).astype(np.float32)
        self.assertTrue(np.allclose(dense, want, atol=1e-6))
        self.assertEqual(g.activeVoxelCount(), int((want > 0).sum()))
        self.assertGreater((want == 1).sum(), 1000)  # the sphere's inside, not a shell
        # the same placement as the level set
        s = vdb.read(p, "sdf")
        self.assertEqual(list(s.metadata["heatvox_block_min"]), list(g.metadata["heatvox_block_min"]))
        with self.assertRaises(ValueError):
            self.grid.write_vdb(os.path.join(self.dir, "bad.vdb"), fog="sdf")
        self.assertFalse(os.path.exists(os.path.join(self.dir, "bad.vdb")))

    def test_write_vdb_should_match_the_command(self):
        hvtest.need_pyopenvdb()
        ref = os.path.join(self.dir, "cmd.vdb")
        hvtest.run("sdf", self.mesh, "-o", ref, "--res", "32", "--band", "2.5", "--dense", "-q")
        mine = os.path.join(self.dir, "dense.vdb")
        self.grid.write_vdb(mine, dense=True)
        a, da = read_vdb_dense(ref, "sdf", self.grid.shape)
        b, db = read_vdb_dense(mine, "sdf", self.grid.shape)
        self.assertTrue(hvtest.bits_equal(da, db))
        self.assertEqual(a.activeVoxelCount(), b.activeVoxelCount())
        self.assertEqual(b.activeVoxelCount(), self.grid.values.size)
        self.assertEqual(a.background, b.background)
        self.assertEqual(a.gridClass, b.gridClass)

    def test_unsigned_and_own_arrays_should_be_float_grids(self):
        vdb = hvtest.need_pyopenvdb()
        u = heatvox.sdf(self.mesh, res=16, unsigned=True)
        p = os.path.join(self.dir, "u.vdb")
        u.write_vdb(p, name="udf", metadata={"note": "unsigned"})
        g, dense = read_vdb_dense(p, "udf", u.shape)
        self.assertEqual(g.gridClass, vdb.GridClass.UNKNOWN)
        self.assertTrue(hvtest.bits_equal(dense, u.values))
        _, meta = vdb.readAll(p)
        self.assertEqual(meta["note"], "unsigned")

        own = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
        mine = heatvox.Grid(own, 0.25, origin=(1, 2, 3), solid=own > 20)
        self.assertTrue(np.shares_memory(mine.values, own))  # no copy
        p = os.path.join(self.dir, "own.vdb")
        mine.write_vdb(p)
        g, dense = read_vdb_dense(p, "values", own.shape)
        self.assertTrue(hvtest.bits_equal(dense, own))
        obst = vdb.read(p, "obstacles")
        self.assertEqual(obst.activeVoxelCount(), 3)
        # a float64 or strided array is converted once
        conv = heatvox.Grid(own[:, :, ::2].astype(np.float64), 1.0)
        self.assertEqual(conv.values.dtype, np.float32)
        self.assertTrue(conv.values.flags.c_contiguous)

    def test_write_errors_should_name_the_file(self):
        p = os.path.join(self.dir, "no_such_dir", "g.vdb")
        with self.assertRaises(heatvox.Error) as cm:
            self.grid.write_vdb(p)
        self.assertIn(p, str(cm.exception))
        with self.assertRaises(heatvox.Error) as cm:
            self.grid.write_npy(os.path.join(self.dir, "no_such_dir", "g.npy"))
        self.assertIn("no_such_dir", str(cm.exception))

    def test_bad_grid_arguments_should_raise_before_calling_c(self):
        with self.assertRaises(ValueError):
            heatvox.Grid(np.zeros(5, np.float32), 1.0)
        with self.assertRaises(ValueError):
            heatvox.Grid(np.zeros((2, 2, 2), np.float32), 0.0)
        with self.assertRaises(ValueError):
            heatvox.Grid(np.zeros((2, 2, 2), np.float32), 1.0, solid=np.zeros((2, 2), bool))
        with self.assertRaises(ValueError):
            heatvox.Grid(np.zeros((2, 2, 2), np.float32), 1.0, origin=(0, 0))
        with self.assertRaises(ValueError):
            self.grid.write_vdb(os.path.join(self.dir, "x.vdb"), band=-1)


class ToMesh(unittest.TestCase):
    def test_to_mesh_should_give_a_closed_outward_mesh(self):
        g = heatvox.sdf(hvtest.scene("meshes/sphere_holes_flips.obj"), res=32)
        v, f = g.to_mesh()
        self.assertEqual(v.dtype, np.float64)
        self.assertEqual(f.dtype, np.uint32)
        r = heatvox.mesh_report(v, f)
        self.assertEqual(r["boundary_edges"], 0)
        self.assertEqual(r["nonmanifold_edges"], 0)
        self.assertEqual(r["inconsistent_edges"], 0)
        # the unit sphere: volume 4/3 pi, vertices on the zero set
        self.assertAlmostEqual(r["signed_volume"], 4 / 3 * np.pi, delta=0.05)
        rad = np.linalg.norm(v - v.mean(axis=0), axis=1)
        self.assertLess(np.abs(rad - 1).max(), 0.5 * g.voxel_size)
        va, fa = g.to_mesh(adaptivity=0.8)
        self.assertLess(len(fa), len(f))
        self.assertEqual(heatvox.mesh_report(va, fa)["boundary_edges"], 0)
        with self.assertRaises(ValueError):
            g.to_mesh(adaptivity=2)
        with self.assertRaises(ValueError):
            heatvox.Grid(np.zeros((4, 4), np.float32), 1.0).to_mesh()

    def test_to_mesh_without_a_crossing_should_raise(self):
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.Grid(np.ones((8, 8, 8), np.float32), 1.0).to_mesh()
        self.assertEqual(cm.exception.status, heatvox.Status.INVALID_ARG)


if __name__ == "__main__":
    unittest.main()

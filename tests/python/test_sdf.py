"""heatvox.sdf against `heatvox sdf --npy`, bit for bit; the values view;
progress and cancelling; argument errors."""

import gc
import os
import unittest

import numpy as np

import heatvox
import hvtest


def command_npy(mesh, *opts):
    d = hvtest.tmpdir()
    npy = os.path.join(d, "c.npy")
    hvtest.run("sdf", mesh, "-o", os.path.join(d, "c.vdb"), "--npy", npy, "-q", *opts)
    return np.load(npy)


class SameAsCommand(unittest.TestCase):
    def check(self, mesh, opts, **kw):
        ref = command_npy(hvtest.scene(mesh), *opts)
        v, f = heatvox.read_mesh(hvtest.scene(mesh))
        g = heatvox.sdf(v, f, **kw)
        self.assertEqual(g.values.shape, ref.shape)
        hvtest.assert_bits_equal(self, g.values, ref, "%s %s" % (mesh, opts))
        return g

    def test_sphere_should_equal_command_npy_bit_for_bit(self):
        g = self.check("meshes/sphere_holes_flips.obj", ["--res", "40"], res=40)
        self.assertTrue(g.levelset)
        self.assertEqual(g.name, "sdf")
        self.assertEqual(g.stats["n"], [g.shape[2], g.shape[1], g.shape[0]])
        self.assertGreater(g.stats["repair"]["holes_filled"], 0)

    def test_broken_soup_with_band_voxel_size_and_pad_should_equal_command_npy(self):
        g = self.check(
            "meshes/torus_soup.obj", ["--voxel-size", "0.08", "--pad", "6", "--band", "4"], voxel_size=0.08, pad=6, band=4
        )
        self.assertEqual(g.band, 4.0)
        self.assertAlmostEqual(g.voxel_size, 0.08)

    def test_bbox_and_backend_mg_should_equal_command_npy(self):
        g = self.check(
            "meshes/torus_holes.obj",
            ["--bbox", "-1.5", "-1.5", "-1", "1.5", "1.5", "1", "--res", "32", "--backend", "mg"],
            bbox=(-1.5, -1.5, -1, 1.5, 1.5, 1),
            res=32,
            backend="mg",
        )
        self.assertEqual(g.origin, (-1.5, -1.5, -1.0))
        self.assertAlmostEqual(g.voxel_size, 3.0 / 32)
        self.assertEqual(g.stats["backend"], "mg")

    def test_unsigned_heat_and_no_repair_should_equal_command_npy(self):
        g = self.check("meshes/sphere_half_flipped.obj", ["--res", "32", "--unsigned"], res=32, unsigned=True)
        self.assertFalse(g.levelset)
        self.assertGreaterEqual(float(g.values.min()), 0.0)
        self.check("meshes/sphere_half_flipped.obj", ["--res", "32", "--heat", "--t-scale", "2"], res=32, heat=True, t_scale=2)
        self.check("meshes/torus_holes.obj", ["--res", "32", "--no-repair", "--domed-caps"], res=32, repair=False, domed_caps=True)

    def test_sign_should_equal_command_npy_and_be_reported(self):
        g = self.check("meshes/torus_holes.obj", ["--res", "32", "--sign", "winding"], res=32, sign="winding")
        self.assertEqual(g.stats["sign"], "winding")
        self.assertGreater(g.stats["winding_evals"], 0)
        g = self.check("meshes/torus_holes.obj", ["--res", "32", "--sign", "heat"], res=32, sign="heat")
        self.assertEqual(g.stats["sign"], "heat")
        self.assertEqual(g.stats["winding_evals"], 0)
        self.assertIsNone(heatvox.sdf(hvtest.scene("meshes/torus_holes.obj"), res=16, unsigned=True).stats["sign"])

    def test_offset_shell_and_close_should_equal_command_npy(self):
        self.check("meshes/torus_holes.obj", ["--res", "40", "--offset", "0.1"], res=40, offset=0.1)
        self.check("meshes/torus_holes.obj", ["--res", "40", "--shell", "0.08"], res=40, shell=0.08)
        self.check("meshes/torus_soup.obj", ["--res", "40", "--close", "0.1"], res=40, close=0.1)

    def test_path_form_should_equal_array_form(self):
        path = hvtest.scene("meshes/sphere_holes_flips.obj")
        a = heatvox.sdf(path, res=24)
        b = heatvox.sdf(*heatvox.read_mesh(path), res=24)
        self.assertTrue(hvtest.bits_equal(a.values, b.values))

    def test_band_only_should_keep_the_band_and_clamp_the_rest(self):
        path = hvtest.scene("meshes/sphere_holes_flips.obj")
        full = heatvox.sdf(path, res=32)
        band = heatvox.sdf(path, res=32, band_only=3)
        h = full.voxel_size
        near = np.abs(full.values) < 3 * h
        self.assertTrue(np.array_equal(full.values[near], band.values[near]))
        self.assertTrue(np.array_equal(np.sign(full.values), np.sign(band.values)))
        self.assertLessEqual(float(np.abs(band.values).max()), 4 * h * (1 + 1e-6))


class Tiles(unittest.TestCase):
    """heatvox.sdf_vdb: the narrow band in tiles, written without the dense block."""

    def active(self, path):
        vdb = hvtest.need_pyopenvdb()
        g = vdb.read(path, "sdf")
        return {it.min: it.value for it in g.citerOnValues() if it.count == 1}, g

    def test_sdf_vdb_should_equal_the_command_and_the_dense_band(self):
        mesh = hvtest.scene("meshes/torus_holes.obj")
        d = hvtest.tmpdir()
        cmd, mine = os.path.join(d, "c.vdb"), os.path.join(d, "p.vdb")
        hvtest.run("sdf", mesh, "-o", cmd, "--res", "40", "-q")
        stats = heatvox.sdf_vdb(mesh, path=mine, res=40, metadata={"k": "v"})
        self.assertEqual(stats["sign"], "winding")
        self.assertGreater(stats["tiles"], 0)
        a, ga = self.active(cmd)
        b, gb = self.active(mine)
        self.assertEqual(a, b)
        self.assertEqual(len(b), stats["active_voxels"])
        self.assertEqual(gb.gridClass, "level set")
        _, meta = hvtest.need_pyopenvdb().readAll(mine)
        self.assertEqual(meta.get("k"), "v")
        dense = heatvox.sdf(mesh, res=40, band_only=3, sign="winding")
        v = dense.values  # (z, y, x)
        for (i, j, k), val in b.items():
            self.assertEqual(np.float32(val), v[k, j, i])
        h = dense.voxel_size
        self.assertEqual(int(np.count_nonzero(np.abs(v) < 3 * h)), len(b))

    def test_sdf_vdb_should_refuse_what_needs_the_dense_block_and_leave_nothing(self):
        mesh = hvtest.scene("meshes/torus_holes.obj")
        d = hvtest.tmpdir()
        with self.assertRaises(ValueError):
            heatvox.sdf_vdb(mesh, path=os.path.join(d, "x.vdb"), sign="heat")
        with self.assertRaises(TypeError):
            heatvox.sdf_vdb(mesh)
        bad = os.path.join(d, "no", "such", "dir", "x.vdb")
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.sdf_vdb(mesh, path=bad, res=16)
        self.assertIn(bad, str(cm.exception))
        self.assertEqual(os.listdir(d), [])


class ValuesView(unittest.TestCase):
    def test_values_should_be_a_view_of_the_library_buffer(self):
        g = heatvox.sdf(hvtest.scene("meshes/sphere_holes_flips.obj"), res=16)
        a, b = g.values, g.values
        self.assertTrue(np.shares_memory(a, b))
        self.assertFalse(a.flags.owndata)
        self.assertEqual(a.dtype, np.float32)
        self.assertTrue(a.flags.c_contiguous and a.flags.writeable)
        a[0, 0, 0] = 123.0
        self.assertEqual(g.values[0, 0, 0], 123.0)
        # the library sees the write: it is in the file it writes
        p = os.path.join(hvtest.tmpdir(), "w.npy")
        g.write_npy(p)
        self.assertEqual(np.load(p)[0, 0, 0], 123.0)

    def test_values_should_keep_the_grid_alive(self):
        g = heatvox.sdf(hvtest.scene("meshes/sphere_holes_flips.obj"), res=16)
        a = g.values
        keep = a.copy()
        del g
        gc.collect()
        junk = [heatvox.sdf(hvtest.scene("meshes/torus_holes.obj"), res=16) for _ in range(2)]
        self.assertTrue(np.array_equal(a, keep))
        del junk


class Progress(unittest.TestCase):
    mesh = None

    def setUp(self):
        self.mesh = heatvox.read_mesh(hvtest.scene("meshes/torus_holes.obj"))

    def test_progress_should_be_called_with_fractions_and_stages(self):
        seen = []
        heatvox.sdf(*self.mesh, res=24, progress=lambda fr, st: seen.append((fr, st)))
        self.assertGreater(len(seen), 2)
        fr = [s[0] for s in seen]
        self.assertTrue(all(0.0 <= x <= 1.0 for x in fr))
        self.assertEqual(fr, sorted(fr))
        self.assertTrue(all(isinstance(s[1], str) and s[1] for s in seen))
        # restored afterwards: a later call without progress does not call it
        n = len(seen)
        heatvox.sdf(*self.mesh, res=16)
        self.assertEqual(len(seen), n)

    def test_returning_true_should_cancel(self):
        calls = []

        def cancel(fraction, stage):
            calls.append(stage)
            return len(calls) >= 2

        with self.assertRaises(heatvox.Error) as cm:
            heatvox.sdf(*self.mesh, res=24, progress=cancel)
        self.assertEqual(cm.exception.status, heatvox.Status.CANCELLED)
        self.assertEqual(cm.exception.name, "cancelled")
        self.assertEqual(len(calls), 2)

    def test_an_exception_in_the_callback_should_cancel_and_propagate(self):
        class Stop(Exception):
            pass

        def boom(fraction, stage):
            raise Stop(stage)

        with self.assertRaises(Stop):
            heatvox.sdf(*self.mesh, res=24, progress=boom)
        heatvox.sdf(*self.mesh, res=16)  # and the library works on

    def test_progress_must_be_callable(self):
        with self.assertRaises(TypeError):
            heatvox.sdf(*self.mesh, res=16, progress=3)


class Arguments(unittest.TestCase):
    def test_bad_arguments_should_raise_before_calling_c(self):
        v, f = heatvox.read_mesh(hvtest.scene("meshes/sphere_holes_flips.obj"))
        for kw, exc in [
            (dict(res=0), ValueError),
            (dict(res=2.5), TypeError),
            (dict(pad=-1), ValueError),
            (dict(voxel_size=-1), ValueError),
            (dict(bbox=(0, 0, 0, 1, 1)), ValueError),
            (dict(bbox=(0, 0, 0, 1, -1, 1)), ValueError),
            (dict(band=0), ValueError),
            (dict(backend="cuda"), ValueError),
            (dict(heat_coarsen=5), ValueError),
            (dict(sign="parity"), ValueError),
            (dict(threads=-1), ValueError),
            (dict(no_such_option=1), TypeError),
        ]:
            with self.assertRaises(exc, msg=str(kw)):
                heatvox.sdf(v, f, **kw)
        with self.assertRaises(ValueError):
            heatvox.sdf(v[:, :2], f)
        with self.assertRaises(TypeError):
            heatvox.sdf(v)

    def test_missing_mesh_file_should_raise_error_naming_it(self):
        path = os.path.join(hvtest.tmpdir(), "gone.ply")
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.sdf(path)
        self.assertIn(path, str(cm.exception))

    def test_docstrings_should_document_the_public_api(self):
        for obj in (heatvox, heatvox.sdf, heatvox.read_mesh, heatvox.mesh_report, heatvox.distance, heatvox.extend,
                    heatvox.Extender, heatvox.Solver, heatvox.Grid, heatvox.Grid.write_vdb, heatvox.Grid.to_mesh,
                    heatvox.Grid.world_to_index, heatvox.Error, heatvox.mask_from_mesh, heatvox.sdf_vdb):
            self.assertGreater(len(obj.__doc__ or ""), 40, obj)
        self.assertIn("band_only", heatvox.sdf.__doc__)
        self.assertRegex(heatvox.__version__, r"^\d+\.\d+\.\d+$")


if __name__ == "__main__":
    unittest.main()

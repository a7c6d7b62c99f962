"""read_mesh and mesh_report against the command's reader and `heatvox info`."""

import gc
import json
import os
import unittest

import numpy as np

import heatvox
import hvtest


class ReadMesh(unittest.TestCase):
    def test_read_mesh_should_give_float64_vertices_and_uint32_faces(self):
        v, f = heatvox.read_mesh(hvtest.scene("meshes/torus_holes.obj"))
        self.assertEqual(v.dtype, np.float64)
        self.assertEqual(f.dtype, np.uint32)
        self.assertEqual(v.shape[1], 3)
        self.assertEqual(f.shape[1], 3)
        self.assertTrue(v.flags.c_contiguous and f.flags.c_contiguous)
        self.assertLess(int(f.max()), v.shape[0])
        # every vertex used, none repeated (the reader welds and drops unused ones)
        self.assertEqual(len(np.unique(f)), v.shape[0])
        self.assertEqual(len(np.unique(v, axis=0)), v.shape[0])

    def test_read_mesh_should_match_the_obj_text(self):
        d = hvtest.tmpdir()
        p = os.path.join(d, "quad.obj")
        with open(p, "w") as fh:
            fh.write("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 5 5\nf 1 2 3 4\n")
        v, f = heatvox.read_mesh(p)
        self.assertTrue(np.array_equal(v, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]))
        self.assertTrue(np.array_equal(f, [[0, 1, 2], [0, 2, 3]]))  # the quad fanned
        r = heatvox.mesh_report(p)
        self.assertEqual((r["polygons_fanned"], r["unreferenced_vertices"], r["input_vertices"]), (1, 1, 5))
        self.assertEqual(r["boundary_edges"], 4)

    def test_mesh_arrays_should_outlive_every_other_reference(self):
        v, f = heatvox.read_mesh(hvtest.scene("meshes/sphere_holes_flips.obj"))
        first = v[0].copy()
        del f
        gc.collect()
        junk = [np.ones(1000) for _ in range(100)]  # reuse freed memory, if any
        self.assertTrue(np.array_equal(v[0], first))
        del junk

    def test_missing_file_should_raise_error_naming_it(self):
        path = os.path.join(hvtest.tmpdir(), "no_such_mesh.obj")
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.read_mesh(path)
        self.assertEqual(cm.exception.status, heatvox.Status.IO)
        self.assertIn(path, str(cm.exception))
        self.assertIn(path, cm.exception.message)
        self.assertEqual(cm.exception.name, "i/o error")

    def test_malformed_file_should_raise_parse_error_naming_file_and_line(self):
        path = hvtest.scene("meshes/truncated.obj")
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.read_mesh(path)
        self.assertEqual(cm.exception.status, heatvox.Status.PARSE)
        self.assertIn("truncated.obj", cm.exception.message)
        self.assertRegex(cm.exception.message, r"line \d+|:\d+")


class MeshReport(unittest.TestCase):
    def test_report_should_equal_heatvox_info(self):
        for name in ("sphere_holes_flips.obj", "torus_soup.obj", "sphere_half_flipped.obj", "torus_holes.obj"):
            path = hvtest.scene("meshes/" + name)
            info = json.loads(hvtest.run("info", "--json", path))
            from_file = heatvox.mesh_report(path)
            v, f = heatvox.read_mesh(path)
            from_arrays = heatvox.mesh_report(v, f)
            fields = [k for k in from_file if k != "signed_volume"]
            self.assertEqual(len(from_file), 15, "every field of hv_mesh_report")
            for k in fields:
                self.assertEqual(from_file[k], info[k], "%s: %s" % (name, k))
            self.assertAlmostEqual(from_file["signed_volume"], info["signed_volume"], places=12)
            # the arrays are the reader's welded mesh: the same report, minus what
            # only the reader knows
            for k in fields:
                if k not in ("input_vertices", "unreferenced_vertices", "polygons_fanned"):
                    self.assertEqual(from_arrays[k], from_file[k], "%s: %s" % (name, k))

    def test_report_should_weld_and_count_defects_of_arrays(self):
        # two triangles sharing an edge by position only, one flipped, plus a duplicate
        v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
        f = np.array([[0, 1, 2], [3, 4, 5], [0, 1, 2]])
        r = heatvox.mesh_report(v, f)
        self.assertEqual(r["vertices"], 4)
        self.assertEqual(r["triangles"], 3)
        self.assertEqual(r["duplicate_faces"], 1)
        self.assertEqual(r["components"], 1)

    def test_bad_arrays_should_raise_before_calling_c(self):
        v = np.zeros((4, 3))
        with self.assertRaises(ValueError):
            heatvox.mesh_report(v, np.array([[0, 1, 4]]))  # index out of range
        with self.assertRaises(ValueError):
            heatvox.mesh_report(v, np.array([[0, 1, -1]]))
        with self.assertRaises(ValueError):
            heatvox.mesh_report(np.zeros((4, 2)), np.array([[0, 1, 2]]))
        with self.assertRaises(ValueError):
            heatvox.mesh_report(v, np.array([0, 1, 2]))
        with self.assertRaises(TypeError):
            heatvox.mesh_report(v, np.array([[0.0, 1.0, 2.0]]))
        with self.assertRaises(TypeError):
            heatvox.mesh_report(v)

    def test_coordinates_beyond_the_bound_should_raise_numeric_error(self):
        v = np.array([[0, 0, 0], [1e200, 0, 0], [0, 1, 0]], float)
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.mesh_report(v, np.array([[0, 1, 2]]))
        self.assertEqual(cm.exception.status, heatvox.Status.NUMERIC)
        self.assertIn("vertex 1", cm.exception.message)


if __name__ == "__main__":
    unittest.main()

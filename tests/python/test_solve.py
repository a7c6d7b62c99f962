"""heatvox.Solver against the exact answer on cosine modes (the discrete
Laplacian's eigenvectors with Neumann walls), and residuals computed here."""

import unittest

import numpy as np

import heatvox


def mode(shape, h, m):
    """A product of cosines cos(pi m_a (i_a + 1/2) / n_a) on a grid of `shape`
    ((nz, ny, nx) or (ny, nx); m in x, y(, z) order) and its eigenvalue of
    -Laplacian: sum 4/h^2 sin^2(pi m_a / (2 n_a))."""
    axes = list(reversed(shape))
    cs = [np.cos(np.pi * m[a] * (np.arange(axes[a]) + 0.5) / axes[a]) for a in range(len(axes))]
    f = cs[0][None, :]
    f = cs[1][:, None] * f
    if len(shape) == 3:
        f = cs[2][:, None, None] * f[None]
    lam = sum(4 / h**2 * np.sin(np.pi * m[a] / (2 * axes[a])) ** 2 for a in range(len(axes)))
    return f, lam


def apply(u, h, alpha, beta, solid=None):
    """alpha u - beta Laplacian(u), Neumann walls, no flux into solid cells."""
    fluid = np.ones(u.shape, bool) if solid is None else ~solid
    lap = np.zeros_like(u, dtype=np.float64)
    for ax in range(u.ndim):
        n = u.shape[ax]
        lo = [slice(None)] * u.ndim
        hi = [slice(None)] * u.ndim
        lo[ax], hi[ax] = slice(0, n - 1), slice(1, n)
        open_ = fluid[tuple(lo)] & fluid[tuple(hi)]
        d = np.where(open_, u[tuple(hi)] - u[tuple(lo)], 0.0)
        lap[tuple(lo)] += d
        lap[tuple(hi)] -= d
    out = alpha * u - beta * lap / h**2
    return np.where(fluid, out, 0.0)


class ExactModes(unittest.TestCase):
    def test_heat_step_should_divide_a_mode_by_its_eigenvalue(self):
        shape, h = (12, 16, 20), 0.1
        t = 4 * h * h
        f, lam = mode(shape, h, (3, 2, 1))
        for backend, dtype, tol in [("fftw", np.float64, 1e-12), ("fftw", np.float32, 2e-6), ("mg", np.float64, 1e-8)]:
            with heatvox.Solver.heat(shape, h, t, backend=backend, tol=1e-10) as s:
                u = s.solve(f.astype(dtype))
                self.assertEqual(u.dtype, dtype)
                self.assertEqual(s.info.backend, backend)
                self.assertTrue(s.info.converged, s.info)
                err = np.abs(u - f / (1 + t * lam)).max()
                self.assertLess(err, tol, "%s %s: %g" % (backend, np.dtype(dtype).name, err))
        with heatvox.Solver.heat(shape, h, t, backend="fftw") as s:
            s.solve(f)
            self.assertEqual(s.info.reason, "exact")
            self.assertEqual(s.backend, "fftw")

    def test_poisson_should_give_the_mean_free_solution(self):
        shape, h = (24, 32), 1.0 / 32
        f, lam = mode(shape, h, (2, 3))
        rng = np.random.default_rng(3)
        g = rng.normal(size=shape)
        for backend in ("fftw", "mg"):
            with heatvox.Solver.poisson(shape, h, backend=backend, tol=1e-10) as s:
                u = s.solve(f)
                self.assertLess(np.abs(u - f / lam).max(), 1e-8, backend)
                v = s.solve(g)  # the solver is reused: the mean of g is projected out
                self.assertLess(abs(v.mean()), 1e-9)
                r = apply(v, h, 0.0, 1.0) - (g - g.mean())
                self.assertLess(np.linalg.norm(r) / np.linalg.norm(g - g.mean()), 1e-8)

    def test_solid_cells_should_carry_no_flux(self):
        shape, h, t = (20, 20, 20), 0.05, 4 * 0.05**2
        solid = np.zeros(shape, bool)
        solid[:, 8:12, 5:15] = True
        f = np.random.default_rng(4).normal(size=shape)
        with heatvox.Solver.heat(shape, h, t, solid, tol=1e-9) as s:
            self.assertEqual(s.backend, "mg")
            u = s.solve(f)
            info = s.info
        self.assertTrue(info.converged)
        self.assertTrue(np.all(u[solid] == 0))
        r = apply(u, h, 1.0, t, solid) - np.where(solid, 0, f)
        rel = np.linalg.norm(r) / np.linalg.norm(np.where(solid, 0, f))
        self.assertLess(rel, 1e-8)
        self.assertAlmostEqual(rel, info.relres, delta=max(1e-10, 0.1 * info.relres))
        self.assertAlmostEqual(info.history[0], 1.0, places=12)
        self.assertEqual(len(info.history), info.iterations + 1)
        self.assertTrue(all(b < a for a, b in zip(info.history, info.history[1:])))
        with self.assertRaises(heatvox.Error) as cm:
            heatvox.Solver.heat(shape, h, t, solid, backend="fftw")
        self.assertEqual(cm.exception.status, heatvox.Status.UNSUPPORTED)

    def test_a_good_guess_should_need_no_iteration(self):
        shape, h, t = (16, 16, 16), 1 / 16, 4 / 256
        f, lam = mode(shape, h, (1, 1, 1))
        exact = f / (1 + t * lam)
        with heatvox.Solver.heat(shape, h, t, backend="mg", nonzero_guess=True, tol=1e-8) as s:
            u = exact.copy()
            s.solve(f, out=u)
            self.assertLessEqual(s.info.iterations, 1)
            cold = np.zeros(shape)
            s.solve(f, out=cold)
            self.assertGreater(s.info.iterations, 1)

    def test_coarse_levels_should_keep_thin_walls(self):
        # Walls one cell thick with gaps at opposite ends: aggregation solves
        # in a few iterations what the geometric levels take many for.
        n = 40
        solid = np.zeros((n, n, n), np.uint8)
        solid[:, : n - 5, n // 3] = 1
        solid[:, 5:, 2 * n // 3] = 1
        f = np.random.default_rng(3).standard_normal((n, n, n)) * (solid == 0)
        its = {}
        for coarse in ("geometric", "aggregation"):
            with heatvox.Solver.poisson((n, n, n), 1.0 / n, solid, backend="mg", coarse=coarse, tol=1e-8) as s:
                u = s.solve(f)
                its[coarse] = s.info.iterations
                self.assertLessEqual(s.info.relres, 1e-8)
                self.assertTrue(np.all(u[solid == 1] == 0))
        self.assertLessEqual(its["aggregation"], 10)
        self.assertGreater(its["geometric"], its["aggregation"] + 4)
        with self.assertRaises(ValueError):
            heatvox.Solver((8, 8), 1.0, coarse="algebraic")

    def test_errors(self):
        with heatvox.Solver.heat((8, 8), 1.0, 1.0) as s:
            f = np.zeros((8, 8))
            f[3, 3] = np.nan
            with self.assertRaises(heatvox.Error) as cm:
                s.solve(f)
            self.assertEqual(cm.exception.status, heatvox.Status.NUMERIC)
            with self.assertRaises(ValueError):
                s.solve(np.zeros((8, 9)))
            with self.assertRaises(ValueError):
                s.solve(np.zeros((8, 8)), out=np.zeros((8, 8), np.float32))
        with self.assertRaises(ValueError):
            s.solve(np.zeros((8, 8)))  # closed
        with self.assertRaises(ValueError):
            heatvox.Solver((8, 8, 8, 8), 1.0)
        with self.assertRaises(ValueError):
            heatvox.Solver((8, 8), 1.0, beta=0)
        with self.assertRaises(ValueError):
            heatvox.Solver((8, 8), 1.0, smoother="sor")


if __name__ == "__main__":
    unittest.main()

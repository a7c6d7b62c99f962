/*
 * Private: the multigrid hierarchy on an OpenCL device, uploaded once from the
 * host hierarchy (mg_setup.c) so that it coarsens exactly like the CPU backend,
 * and the float V-cycle run entirely on the device's in-order queue (no host
 * synchronization inside a cycle; the bottom level is solved by a one-work-
 * group CG kernel, or on the host where the device lacks fp64). The launchers are separate so that tests can compare each
 * kernel with the CPU code.
 */
#ifndef HV_SOLVE_CL_MG_H
#define HV_SOLVE_CL_MG_H

#include "cl/cl_core.h"
#include "solve/mg/mg_agg.h"
#include "solve/mg/mg_level.h"

/* The solver's kernels (kernels/mg.cl, agg.cl, fine.cl) as one module
 * (cl_module.c), launched by these indices; the fine level's double kernels
 * exist only on fp64 handles. hv__clmg_create opens it. */
extern const hv_cl_module hv__clsolve_module;
#define HV_CLSOLVE (&hv__clsolve_module)
enum {
    HV_K_MG_APPLY,
    HV_K_MG_RESIDUAL,
    HV_K_MG_RBGS,
    HV_K_MG_CHEB,
    HV_K_MG_JACOBI,
    HV_K_MG_JACOBI0,
    HV_K_MG_RESTRICT_RESIDUAL,
    HV_K_MG_RESTRICT,
    HV_K_MG_RESTRICT_TRANSPOSE,
    HV_K_MG_PROLONG,
    HV_K_MG_PROLONG_W,
    HV_K_MG_PROLONG_X2,
    HV_K_MG_BOTTOM_CG,
    HV_K_AGG_SPMV,
    HV_K_AGG_APPLY,
    HV_K_AGG_RESIDUAL,
    HV_K_AGG_CHEB,
    HV_K_AGG_PROLONG,
    HV_K_AGG_SCALE,
    HV_K_AGG_RESTRICT0,
    HV_K_AGG_INJECT0,
    HV_K_AGG_PROLONG0,
    HV_K_FINE_RESIDUAL, /* fp64 only from here */
    HV_K_FINE_APPLY,
    HV_K_FINE_ADD,
    HV_K_FINE_F2D,
    HV_K_FINE_PCG_UPDATE,
    HV_K_FINE_XPAY,
    HV_K_FINE_D2F,
    HV_K_FINE_MASK
};

typedef struct hv_clmg_level {
    int n[3];
    size_t count;
    int plain;
    int coarsen[3];
    double c[3];
    double lmax;
    cl_int N[4];    /* (nx, ny, nz, plain) */
    cl_float C[4];  /* (cx, cy, cz, alpha) */
    cl_mem a, w[3]; /* NULL on plain levels */
    cl_mem u[2];    /* u[cur] is the iterate; u[1] only for Jacobi/Chebyshev */
    int cur;
    cl_mem f, d;       /* right-hand side; Chebyshev direction (not with RBGS) */
    cl_mem r, pn;      /* symmetric cycle only (not on the bottom level): the residual,
                              and 1 / prolongation weight sum per cell when the next level is
                              weighted (NULL otherwise; hv__mg_prolong_norm) */
    size_t g[2], l[2]; /* range over the cells */
} hv_clmg_level;

/* The coarse levels by smoothed aggregation on the device (cl_agg.c), uploaded
 * from the host's mg_agg: CSR rows (uint row starts) of A, P and P^T per level
 * below the fine one, the fine level's aggregates and members, and work. */
typedef struct hv_clagg_level {
    int n;
    cl_mem rp, ci, v;         /* A */
    cl_mem plain, toff, tval; /* rows that are the template (level 1; NULL elsewhere) */
    int tn;
    /* without P (a level of template rows): the transfers from A, as the fine level's */
    cl_mem agg, mrp, mem, t, s;
    double wp;
    cl_mem prp, pci, pv; /* P from the next level (not on the last) */
    cl_mem rrp, rci, rv; /* P^T */
    cl_mem dinv, u, f, r, d;
    double lmax;
} hv_clagg_level;

typedef struct hv_clagg {
    mg_agg *host; /* the hierarchy on the host: sizes, the bottom's Cholesky factor */
    int nlev;
    hv_clagg_level lv[MG_AGG_MAX_LEVELS];
    cl_mem agg0, mrp0, mem0, dinv0, r0, t0, s0; /* the fine level's transfers */
    int n0, n1;
    double wp0;
    float *bf, *bu; /* the bottom's right-hand side and solution on the host */
} hv_clagg;

typedef struct hv_clmg {
    hv_cl *cl;
    int dim;
    double alpha;
    int nlev;
    hv_clmg_level lv[MG_MAX_LEVELS];
    hv_smoother smoother;
    int pre, post;
    int sym; /* r and pn are allocated: vcycle(sym) restricts with P^T */
    /* bottom level: regions (Poisson), 1/cells per region, CG scratch */
    int bnregion;
    cl_mem bregion, brinv, bscr;
    size_t bl;
    /* devices without fp64: the bottom level solved on the host in double
     * (hb: a copy of the host hierarchy's bottom level; hf, hw: its float
     * right-hand side and solution, and CG vectors) */
    int host_bottom;
    mg_level hb;
    float *hf;
    double *hw;
    hv_clagg *agg; /* coarse levels by aggregation (solid cells), or NULL */
} hv_clmg;

/* Uploads H's coefficients and allocates the level vectors; with sym also
 * what the symmetric cycle of PCG needs (a residual vector per level and the
 * prolongation renormalization, computed on the host as mg_backend.c does). On failure
 * m holds nothing to free. */
hv_status hv__clmg_create(hv_clmg *m, hv_cl *cl, const mg_hierarchy *H, hv_smoother smoother,
                          int pre, int post, int sym);
void hv__clmg_destroy(hv_clmg *m);

/* Level kernels on level l's coefficients. */
void hv__clmg_apply(hv_clmg *m, int l, cl_mem u, cl_mem y);
void hv__clmg_residual(hv_clmg *m, int l, cl_mem u, cl_mem f, cl_mem r);
/* steps smoothing steps on lv[l].u[cur] for lv[l].f, as the CPU's smooth()
 * (mg_cycle.c); zero: from u = 0, whatever u[cur] holds (Jacobi and
 * Chebyshev then skip reading it). */
void hv__clmg_smooth(hv_clmg *m, int l, int steps, int reverse, int zero);
/* lv[l+1].f = restriction of the residual lv[l].f - A lv[l].u[cur]. */
void hv__clmg_restrict_residual(hv_clmg *m, int l);
/* lv[l+1].f = P^T (pn .* lv[l].r) / 2^(coarsened axes), as
 * hv__mg_restrict_transpose (mg_transfer.c) (needs sym at creation). */
void hv__clmg_restrict_transpose(hv_clmg *m, int l);
/* dst (level l+1) = mean of the children of src (level l). */
void hv__clmg_restrict(hv_clmg *m, int l, cl_mem src, cl_mem dst);
/* lv[l].u[cur] += P lv[l+1].u[cur] */
void hv__clmg_prolong(hv_clmg *m, int l);
/* lv[nlev-1].u[cur] = CG solution for lv[nlev-1].f: on the device in one
 * work-group, or on devices without fp64 on the host in double (a host
 * synchronization inside the cycle). */
void hv__clmg_bottom(hv_clmg *m);

/* One V-cycle on level l (u from zero unless guess; sym, for use as a CG
 * preconditioner, restricts with P^T when created with sym and reverses the
 * post-smoothing order), and full multigrid
 * for lv[0].f, as mg_backend.c. The result is lv[0].u[lv[0].cur]. */
void hv__clmg_vcycle(hv_clmg *m, int l, int guess, int sym);
/* Builds the aggregation hierarchy under host fine level F (as the CPU
 * backend's, mg_agg.h) and uploads it; the symmetric cycle then uses it in
 * place of the geometric levels. m->agg stays NULL where aggregation does not
 * apply (a grid too small). */
hv_status hv__clagg_create(hv_clmg *m, const mg_level *F, int dim, double alpha);
void hv__clagg_destroy(hv_clmg *m);
/* lv[0].u[cur] += the aggregation hierarchy's correction of residual lv[0]'s
 * r0 (one symmetric V-cycle on the levels below, as agg_cycle.c). */
void hv__clagg_correct(hv_clmg *m);
void hv__clmg_fmg(hv_clmg *m);

#endif

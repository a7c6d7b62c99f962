// bench_ref_cgal: CGAL's Poisson surface reconstruction (Kazhdan, Bolitho and
// Hoppe 2006, as CGAL 5.5 implements it: the implicit function on a refined
// Delaunay triangulation, solved with Eigen's conjugate gradient, its zero
// level meshed by CGAL's surface mesher), the reference that `heatvox bench
// points` measures heatvox's reconstruction from oriented points against.
//
//   bench_ref_cgal IN.xyz OUT.ply --h H [--unoriented]
//
// IN.xyz: one point a line, "x y z nx ny nz" ('#' starts a comment; with
// --unoriented "x y z" will do, and normals given are ignored: they are
// estimated by jet fitting and oriented along a minimum spanning tree, CGAL's
// jet_estimate_normals and mst_orient_normals, as its Poisson example does,
// and the points the tree leaves unoriented are dropped). OUT.ply:
// the mesh, binary little-endian PLY (double coordinates), written under a
// temporary name and renamed when complete. One JSON line on stdout: points,
// triangles, h, with --unoriented normals_seconds, orient_seconds and
// oriented (the points kept), poisson_seconds (the implicit function), mesh_seconds (the
// surface mesher), compute_seconds (both), seconds (the whole run, reading and
// writing included), peak_rss_mb. Exit codes: 0 success, 1 failure, 2 usage.
//
// A program of its own, built by `make bench` alone: CGAL's headers take a
// minute to compile, and neither the library nor the command needs them.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/IO/facets_in_complex_2_to_triangle_mesh.h>
#include <CGAL/Implicit_surface_3.h>
#include <CGAL/Poisson_reconstruction_function.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_default_triangulation_3.h>
#include <CGAL/jet_estimate_normals.h>
#include <CGAL/make_surface_mesh.h>
#include <CGAL/mst_orient_normals.h>

#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace
{

typedef CGAL::Exact_predicates_inexact_constructions_kernel Kernel;
typedef Kernel::FT FT;
typedef Kernel::Point_3 Point;
typedef Kernel::Vector_3 Vector;
typedef Kernel::Sphere_3 Sphere;
typedef std::pair<Point, Vector> Point_with_normal;
typedef CGAL::Poisson_reconstruction_function<Kernel> Poisson;
typedef CGAL::Surface_mesh_default_triangulation_3 STr;
typedef CGAL::Surface_mesh_complex_2_in_triangulation_3<STr> C2t3;
typedef CGAL::Implicit_surface_3<Kernel, Poisson> Surface_3;
typedef CGAL::Surface_mesh<Point> Mesh;

const char *PROG = "bench_ref_cgal";
// The neighbours of --unoriented's jet fit and spanning tree: CGAL's Poisson
// reconstruction example's 18.
const int NEIGHBOURS = 18;

// A failure to report: the message names the file and the problem.
struct Fail {
    std::string msg;
};

[[noreturn]] void fail(const std::string &msg) { throw Fail{msg}; }

double now()
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

// The usage on stdout for --help (exit 0), else why and the usage on stderr
// (exit 2).
int usage(const char *why)
{
    std::FILE *f = why ? stderr : stdout;
    if (why)
        std::fprintf(stderr, "%s: %s\n", PROG, why);
    std::fprintf(f,
                 "usage: %s IN.xyz OUT.ply --h H [--unoriented]\n"
                 "CGAL's Poisson surface reconstruction of the oriented points of IN.xyz\n"
                 "(x y z nx ny nz a line), meshed at the resolution of a grid of voxel size H,\n"
                 "written to OUT.ply; one JSON line of times and sizes on stdout.\n"
                 "--unoriented: the normals estimated (jet_estimate_normals) and oriented\n"
                 "(mst_orient_normals), %d neighbours each, from the points alone (x y z a\n"
                 "line will do; normals given are ignored).\n",
                 PROG, NEIGHBOURS);
    return why ? 2 : 0;
}

// One line of IN.xyz: 0 for a blank or comment line, else how many numbers
// (6, or 3 when bare is allowed).
int parse_line(const std::string &line, const std::string &where, bool bare, double v[6])
{
    const size_t hash = line.find('#');
    std::istringstream in(line.substr(0, hash));
    int got = 0;
    std::string word;
    while (in >> word) {
        if (got == 6)
            fail(where + ": more than 6 numbers (x y z nx ny nz)");
        char *end = nullptr;
        v[got] = std::strtod(word.c_str(), &end);
        if (*end || !std::isfinite(v[got]))
            fail(where + ": '" + word + "' is not a finite number");
        got++;
    }
    if (got != 0 && got != 6 && !(bare && got == 3))
        fail(where + ": " + std::to_string(got) + " numbers, " + (bare ? "3 or " : "") +
             "6 expected (x y z nx ny nz)");
    return got;
}

// The points of IN.xyz; without their normals (zero vectors) when bare.
std::vector<Point_with_normal> read_xyz(const char *path, bool bare)
{
    std::ifstream in(path);
    if (!in)
        fail(std::string(path) + ": cannot open: " + std::strerror(errno));
    std::vector<Point_with_normal> pts;
    std::string line;
    for (size_t no = 1; std::getline(in, line); no++) {
        double v[6];
        const std::string where = std::string(path) + ":" + std::to_string(no);
        const int got = parse_line(line, where, bare, v);
        if (!got)
            continue;
        if (bare) {
            pts.emplace_back(Point(v[0], v[1], v[2]), Vector(0, 0, 0));
            continue;
        }
        const Vector n(v[3], v[4], v[5]);
        if (n.squared_length() == 0)
            fail(where + ": zero normal");
        pts.emplace_back(Point(v[0], v[1], v[2]), n / std::sqrt(n.squared_length()));
    }
    if (in.bad())
        fail(std::string(path) + ": read error");
    if (pts.size() < 4)
        fail(std::string(path) + ": " + std::to_string(pts.size()) +
             " points; the reconstruction needs at least 4");
    return pts;
}

struct Times {
    double normals = 0, orient = 0, poisson = 0, mesh = 0;
};

// --unoriented: the normals by jet fitting, their signs along the minimum
// spanning tree; the points it leaves unoriented dropped (as CGAL's example
// does). Fails when none is oriented.
void estimate_normals(std::vector<Point_with_normal> &pts, Times &t)
{
    const auto params =
        CGAL::parameters::point_map(CGAL::First_of_pair_property_map<Point_with_normal>())
            .normal_map(CGAL::Second_of_pair_property_map<Point_with_normal>());
    double t0 = now();
    CGAL::jet_estimate_normals<CGAL::Sequential_tag>(pts, NEIGHBOURS, params);
    t.normals = now() - t0;
    t0 = now();
    const auto unoriented = CGAL::mst_orient_normals(pts, NEIGHBOURS, params);
    pts.erase(unoriented, pts.end());
    t.orient = now() - t0;
    if (pts.empty())
        fail("mst_orient_normals oriented no point");
}

// The surface mesher's criteria for the resolution of a grid of voxel size h.
// A grid's zero level mesh (one vertex per crossed voxel) has edges of about
// h to 1.4 h and stays within a small fraction of h of the surface it samples.
// The radius bound (of the facets' surface Delaunay balls, about their
// circumradii) h/sqrt(2) gives facets of edge 1.2 h when equilateral (1.4 h at
// most), and about as many triangles as heatvox's mesh of the same surface
// (the bunny at 64 and 128 voxels: 4% fewer). The distance bound h/4 (CGAL's
// default is 0.375 of the point spacing, with a radius bound that never
// binds) asks for more only where the surface curves on the scale of a voxel
// (0.1% more triangles on the bunny at 128 than with 4 h). The angle bound is
// CGAL's default, 20 degrees.
CGAL::Surface_mesh_default_criteria_3<STr> criteria_for(double h)
{
    return CGAL::Surface_mesh_default_criteria_3<STr>(20.0, h / std::sqrt(2.0), h / 4);
}

// As CGAL's poisson_surface_reconstruction_delaunay, with the criteria above:
// the function's zero level (the median of its values at the points) inside
// a sphere of 5 times the triangulation's radius around a point inside.
Mesh reconstruct(const std::vector<Point_with_normal> &pts, double h, Times &t)
{
    double t0 = now();
    Poisson function(pts.begin(), pts.end(), CGAL::First_of_pair_property_map<Point_with_normal>(),
                     CGAL::Second_of_pair_property_map<Point_with_normal>());
    if (!function.compute_implicit_function())
        fail("the Poisson solve failed (Eigen's conjugate gradient did not converge)");
    t.poisson = now() - t0;
    t0 = now();
    const Point inner = function.get_inner_point();
    const FT radius = 5 * std::sqrt(function.bounding_sphere().squared_radius());
    const FT dichotomy = h / 4 / 1000; // CGAL's: distance bound / 1000
    Surface_3 surface(function, Sphere(inner, radius * radius), dichotomy / radius);
    STr tr;
    C2t3 c2t3(tr);
    CGAL::make_surface_mesh(c2t3, surface, criteria_for(h), CGAL::Manifold_with_boundary_tag());
    if (tr.number_of_vertices() == 0 || c2t3.number_of_facets() == 0)
        fail("the surface mesher found no surface");
    Mesh mesh;
    CGAL::facets_in_complex_2_to_triangle_mesh(c2t3, mesh);
    t.mesh = now() - t0;
    return mesh;
}

// The output under ".NAME.tmp-PID" beside it, created before the work so
// that an output that cannot be written fails at once; renamed onto NAME by
// commit, removed when the run fails.
struct Staged {
    std::string path, tmp;
    std::FILE *f = nullptr;

    explicit Staged(const char *name) : path(name)
    {
        const size_t slash = path.rfind('/');
        const size_t cut = slash == std::string::npos ? 0 : slash + 1;
        tmp = path.substr(0, cut) + "." + path.substr(cut) + ".tmp-" + std::to_string(getpid());
        if (!(f = std::fopen(tmp.c_str(), "wb")))
            fail(path + ": cannot create: " + std::strerror(errno));
    }
    ~Staged()
    {
        if (f) {
            std::fclose(f);
            std::remove(tmp.c_str());
        }
    }
    void put(const void *p, size_t n)
    {
        if (std::fwrite(p, 1, n, f) != n)
            fail(path + ": write error: " + std::strerror(errno));
    }
    void commit()
    {
        const bool closed = std::fclose(f) == 0;
        f = nullptr;
        if (!closed || std::rename(tmp.c_str(), path.c_str()) != 0) {
            const std::string why = std::strerror(errno);
            std::remove(tmp.c_str());
            fail(path + ": cannot write: " + why);
        }
    }
};

// Binary little-endian PLY, double coordinates (as heatvox writes them).
void write_ply(Staged &out, const Mesh &m)
{
    std::fprintf(out.f,
                 "ply\nformat binary_little_endian 1.0\ncomment %s: CGAL Poisson reconstruction\n"
                 "element vertex %zu\nproperty double x\nproperty double y\nproperty double z\n"
                 "element face %zu\nproperty list uchar uint vertex_indices\nend_header\n",
                 PROG, (size_t)m.number_of_vertices(), (size_t)m.number_of_faces());
    for (Mesh::Vertex_index v : m.vertices()) { // a fresh mesh: indices 0..n-1, no gaps
        const Point &p = m.point(v);
        const double xyz[3] = {p.x(), p.y(), p.z()};
        out.put(xyz, sizeof xyz);
    }
    for (Mesh::Face_index fc : m.faces()) {
        unsigned char three = 3;
        uint32_t idx[3];
        int k = 0;
        for (Mesh::Vertex_index v : m.vertices_around_face(m.halfedge(fc)))
            idx[k++] = (uint32_t)v;
        out.put(&three, 1);
        out.put(idx, sizeof idx);
    }
    out.commit();
}

// Peak resident memory of this program: Linux's VmHWM, which starts anew at
// exec (getrusage's maximum would count the parent's memory at the fork).
double peak_rss_mb()
{
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.compare(0, 6, "VmHWM:") == 0)
            return std::strtod(line.c_str() + 6, nullptr) / 1024.0;
    struct rusage ru;
    return getrusage(RUSAGE_SELF, &ru) == 0 ? ru.ru_maxrss / 1024.0 : 0;
}

int run(const char *in, const char *out, double h, bool unoriented)
{
    const double t0 = now();
    // The surface mesher starts from random points, by default seeded from the
    // clock: a fixed seed makes the runs repeatable.
    CGAL::get_default_random() = CGAL::Random(1);
    Staged staged(out);
    std::vector<Point_with_normal> pts = read_xyz(in, unoriented);
    const size_t count = pts.size();
    Times t;
    if (unoriented)
        estimate_normals(pts, t);
    const Mesh mesh = reconstruct(pts, h, t);
    write_ply(staged, mesh);
    std::printf("{\"ref\":\"%s\",\"points\":%zu,\"triangles\":%zu,\"h\":%.9g,",
                unoriented ? "cgal-unoriented" : "cgal-poisson", count,
                (size_t)mesh.number_of_faces(), h);
    if (unoriented)
        std::printf("\"normals_seconds\":%.4f,\"orient_seconds\":%.4f,\"oriented\":%zu,", t.normals,
                    t.orient, pts.size());
    std::printf("\"poisson_seconds\":%.4f,\"mesh_seconds\":%.4f,\"compute_seconds\":%.4f,"
                "\"seconds\":%.4f,\"peak_rss_mb\":%.1f}\n",
                t.poisson, t.mesh, t.normals + t.orient + t.poisson + t.mesh, now() - t0,
                peak_rss_mb());
    return 0;
}

} // namespace

int main(int argc, char **argv)
{
    const char *in = nullptr, *out = nullptr;
    double h = 0;
    bool unoriented = false;
    for (int a = 1; a < argc; a++) {
        if (!std::strcmp(argv[a], "--unoriented")) {
            unoriented = true;
        } else if (!std::strcmp(argv[a], "--h")) {
            if (++a == argc)
                return usage("--h needs a voxel size");
            char *end = nullptr;
            h = std::strtod(argv[a], &end);
            if (*end || !(h > 0) || !std::isfinite(h))
                return usage(
                    (std::string("--h needs a positive number, got '") + argv[a] + "'").c_str());
        } else if (!std::strcmp(argv[a], "--help") || !std::strcmp(argv[a], "-h")) {
            return usage(nullptr);
        } else if (argv[a][0] == '-' && argv[a][1]) {
            return usage((std::string("unknown option '") + argv[a] + "'").c_str());
        } else if (!in) {
            in = argv[a];
        } else if (!out) {
            out = argv[a];
        } else {
            return usage(
                (std::string("one input and one output, got '") + argv[a] + "' too").c_str());
        }
    }
    if (!in || !out || h == 0)
        return usage(!in ? "no input" : !out ? "no output" : "--h H is required");
    try {
        return run(in, out, h, unoriented);
    } catch (const Fail &e) {
        std::fprintf(stderr, "%s: %s\n", PROG, e.msg.c_str());
    } catch (const std::bad_alloc &) {
        std::fprintf(stderr, "%s: %s: out of memory\n", PROG, in);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "%s: %s: CGAL: %s\n", PROG, in, e.what());
    }
    return 1;
}

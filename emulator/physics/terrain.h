#pragma once
/// The floor under the vehicles: infinite planes (analytic ray tests, no Bullet collision at all)
/// and static triangle meshes loaded with assimp (OBJ, STL, PLY, glTF, ... with scale and up-axis
/// options) held in a private btCollisionWorld as btBvhTriangleMeshShape, queried by ray only.
/// Every surface has a peak (static) and a sliding friction coefficient; friction patches
/// (polygons in the world x-y plane, e.g. an oil spot) override it where a contact falls inside,
/// the last added patch winning. World frame W: z up, metres.
/// Raycast() is const and allocation-free; Terrain is thread-compatible.

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

class btCollisionWorld;
class btCollisionConfiguration;
class btDispatcher;
class btBroadphaseInterface;
class btCollisionObject;
class btTriangleMesh;
class btBvhTriangleMeshShape;

namespace wheelhil::emulator {

/// Friction of a surface: mu_peak holds a wheel that does not slip, mu_slide applies when sliding
/// fast (see docs/physics.md, slip curve).
struct Friction {
  double mu_peak = 0.8;
  double mu_slide = 0.7;
};

/// Result of a ray query.
struct SurfaceHit {
  Eigen::Vector3d point_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal_W = Eigen::Vector3d::UnitZ();  ///< unit, facing the ray origin
  double distance_m = 0;                                ///< along the (unit) ray direction
  Friction friction;
};

/// Options for a mesh floor.
struct MeshOptions {
  double scale = 1.0;  ///< applied to the file's coordinates
  char up_axis = 'z';  ///< the file's up axis: 'y' (glTF/OBJ habit) or 'z'
  Eigen::Vector3d offset_W = Eigen::Vector3d::Zero();  ///< added after scale and axis change
  Friction friction;
};

/// A polygon (world x-y, counter-clockwise or not) with its own friction.
struct FrictionPatch {
  std::string name;
  std::vector<Eigen::Vector2d> polygon_W;
  Friction friction;
};

class Terrain {
 public:
  /// Largest mesh accepted (all meshes together are not limited): a 4 M-triangle floor is
  /// ~400 MB of collision data.
  static constexpr std::size_t kMaxTriangles = 4'000'000;
  /// Cap on the vertical-ray grid's triangle lists (4 bytes each); a mesh of triangles far larger
  /// than its cells gets a coarser grid, not unbounded lists.
  static constexpr std::uint64_t kMaxGridEntries = std::uint64_t{1} << 25;

  Terrain();
  ~Terrain();
  Terrain(const Terrain&) = delete;
  Terrain& operator=(const Terrain&) = delete;

  /// Infinite plane through point_W with (not necessarily unit) normal_W.
  void AddPlane(const Eigen::Vector3d& normal_W, const Eigen::Vector3d& point_W,
                const Friction& friction);
  /// Loads a mesh with assimp. Throws std::invalid_argument naming the file and the problem
  /// (missing, unreadable, no triangles, bad option).
  void AddMesh(const std::string& path, const MeshOptions& options);
  /// Adds an already triangulated mesh (vertices in W, triangles as index triples). Throws
  /// std::invalid_argument for no or more than kMaxTriangles triangles, an index out of range or
  /// a vertex that is not finite.
  void AddTriangles(const std::vector<Eigen::Vector3d>& vertices_W,
                    const std::vector<std::array<int, 3>>& triangles, const Friction& friction,
                    const std::string& name = "triangles");
  /// Throws std::invalid_argument if the polygon has < 3 vertices or mu is not in [0, 10].
  void AddPatch(const FrictionPatch& patch);

  /// Closest surface along from_W + t*dir_W (dir_W unit), 0 <= t <= max_distance_m.
  [[nodiscard]] bool Raycast(const Eigen::Vector3d& from_W, const Eigen::Vector3d& dir_W,
                             double max_distance_m, SurfaceHit* hit) const noexcept;

  /// Friction at a world point after patches.
  [[nodiscard]] Friction FrictionAt(const Eigen::Vector3d& point_W,
                                    const Friction& base) const noexcept;

  [[nodiscard]] bool has_meshes() const noexcept { return !meshes_.empty(); }
  [[nodiscard]] std::size_t triangle_count() const noexcept { return triangle_count_; }

 private:
  struct Plane {
    Eigen::Vector3d n;
    double d;  // n.x = d on the plane
    Friction friction;
  };
  // A static triangle mesh: Bullet's BVH shape (any ray direction) plus, for the near-vertical
  // rays of the wheels, a uniform x-y grid of triangle lists tested in double precision.
  struct Mesh {
    std::unique_ptr<btTriangleMesh> triangles;
    std::unique_ptr<btBvhTriangleMeshShape> shape;
    std::unique_ptr<btCollisionObject> object;
    Friction friction;
    std::vector<std::array<Eigen::Vector3d, 3>> tris;  // W
    double grid_x0 = 0, grid_y0 = 0, cell_m = 1;
    int nx = 0, ny = 0;
    std::vector<std::uint32_t> cell_start;  // nx*ny + 1
    std::vector<std::uint32_t> cell_tris;
  };
  static bool GridRaycast(const Mesh& mesh, const Eigen::Vector3d& from, const Eigen::Vector3d& dir,
                          double max_distance, double* t, Eigen::Vector3d* normal) noexcept;
  std::vector<Plane> planes_;
  std::vector<Mesh> meshes_;
  std::vector<FrictionPatch> patches_;
  // Per patch (same order): a box around the polygon, checked before the polygon test. Outside
  // [y_lo, y_hi) no edge straddles the point's y (exact); x_lo/x_hi carry a margin above the
  // rounding of the edge-crossing abscissa, so a skipped patch is one the polygon test rejects.
  struct PatchBox {
    double x_lo, x_hi, y_lo, y_hi;
  };
  std::vector<PatchBox> patch_boxes_;
  // Uniform x-y grid over all boxes (at most 64 x 64 cells): per cell the patches whose box
  // touches it, newest first. Cell indices are monotone in x and y, so a point inside a box is
  // always in a cell that lists the patch.
  void RebuildPatchGrid();
  double patch_x0_ = 0, patch_y0_ = 0, patch_inv_cell_ = 1;
  int patch_nx_ = 0, patch_ny_ = 0;
  std::vector<std::uint32_t> patch_cell_start_;  // patch_nx_ * patch_ny_ + 1
  std::vector<std::uint32_t> patch_cell_list_;
  std::size_t triangle_count_ = 0;
  std::unique_ptr<btCollisionConfiguration> config_;
  std::unique_ptr<btDispatcher> dispatcher_;
  std::unique_ptr<btBroadphaseInterface> broadphase_;
  std::unique_ptr<btCollisionWorld> world_;
};

/// Rejects friction values outside 0 <= mu_slide <= mu_peak <= 10 with "where: field: problem".
void ValidateFriction(const Friction& friction, const std::string& where);

}  // namespace wheelhil::emulator

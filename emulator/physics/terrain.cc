#include "emulator/physics/terrain.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include <BulletCollision/NarrowPhaseCollision/btRaycastCallback.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <btBulletCollisionCommon.h>
#include <fmt/format.h>
#include <Eigen/Geometry>
#include <assimp/Importer.hpp>

#include "emulator/physics/collision_configuration.h"

namespace wheelhil::emulator {

namespace {

btVector3 ToBt(const Eigen::Vector3d& v) {
  return btVector3(static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()),
                   static_cast<btScalar>(v.z()));
}
Eigen::Vector3d ToEigen(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

// Closest-hit ray callback over one triangle mesh.
struct ClosestTriangleRay : public btTriangleRaycastCallback {
  ClosestTriangleRay(const btVector3& from, const btVector3& to)
      : btTriangleRaycastCallback(from, to, 0) {}
  btScalar reportHit(const btVector3& hit_normal, btScalar fraction, int /*part*/,
                     int /*triangle*/) override {
    if (fraction < m_hitFraction) {
      normal = hit_normal;
      hit = true;
      return fraction;
    }
    return m_hitFraction;
  }
  btVector3 normal{0, 0, 1};
  bool hit = false;
};

bool InsidePolygon(const std::vector<Eigen::Vector2d>& poly, double x, double y) {
  bool inside = false;
  const std::size_t n = poly.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const auto& a = poly[i];
    const auto& b = poly[j];
    if ((a.y() > y) != (b.y() > y) && x < (b.x() - a.x()) * (y - a.y()) / (b.y() - a.y()) + a.x()) {
      inside = !inside;
    }
  }
  return inside;
}

}  // namespace

void ValidateFriction(const Friction& f, const std::string& where) {
  if (!(std::isfinite(f.mu_peak) && f.mu_peak >= 0 && f.mu_peak <= 10)) {
    throw std::invalid_argument(
        fmt::format("{}: mu_peak ({}) must be finite and in [0, 10]", where, f.mu_peak));
  }
  if (!(std::isfinite(f.mu_slide) && f.mu_slide >= 0 && f.mu_slide <= f.mu_peak)) {
    throw std::invalid_argument(fmt::format(
        "{}: mu_slide ({}) must be finite and in [0, mu_peak={}]", where, f.mu_slide, f.mu_peak));
  }
}

Terrain::Terrain() = default;

Terrain::~Terrain() {
  if (world_) {
    for (auto& m : meshes_) world_->removeCollisionObject(m.object.get());
  }
}

void Terrain::AddPlane(const Eigen::Vector3d& normal_W, const Eigen::Vector3d& point_W,
                       const Friction& friction) {
  ValidateFriction(friction, "plane");
  const double norm = normal_W.norm();
  if (!(norm > 1e-9) || !std::isfinite(norm)) {
    throw std::invalid_argument("plane: normal: must be a finite non-zero vector");
  }
  Plane p{normal_W / norm, 0.0, friction};
  p.d = p.n.dot(point_W);
  planes_.push_back(p);
}

void Terrain::AddTriangles(const std::vector<Eigen::Vector3d>& vertices_W,
                           const std::vector<std::array<int, 3>>& triangles,
                           const Friction& friction, const std::string& name) {
  ValidateFriction(friction, name);
  if (triangles.empty()) {
    throw std::invalid_argument(fmt::format("{}: mesh: contains no triangles", name));
  }
  if (triangles.size() > kMaxTriangles) {
    throw std::invalid_argument(fmt::format("{}: mesh: {} triangles; at most {} are supported",
                                            name, triangles.size(), kMaxTriangles));
  }
  for (std::size_t k = 0; k < vertices_W.size(); ++k) {
    if (!vertices_W[k].allFinite()) {
      throw std::invalid_argument(fmt::format("{}: mesh: vertex {} is not finite", name, k));
    }
  }
  if (!world_) {
    config_ = physics::MakeCollisionConfiguration();
    dispatcher_ = std::make_unique<btCollisionDispatcher>(config_.get());
    broadphase_ = std::make_unique<btDbvtBroadphase>();
    world_ =
        std::make_unique<btCollisionWorld>(dispatcher_.get(), broadphase_.get(), config_.get());
  }
  Mesh mesh;
  mesh.friction = friction;
  mesh.triangles = std::make_unique<btTriangleMesh>(/*use32bitIndices=*/true,
                                                    /*use4componentVertices=*/false);
  const int nv = static_cast<int>(vertices_W.size());
  for (const auto& t : triangles) {
    for (int k : t) {
      if (k < 0 || k >= nv) {
        throw std::invalid_argument(
            fmt::format("{}: mesh: triangle index {} out of range [0, {})", name, k, nv));
      }
    }
    mesh.triangles->addTriangle(ToBt(vertices_W[t[0]]), ToBt(vertices_W[t[1]]),
                                ToBt(vertices_W[t[2]]), /*removeDuplicateVertices=*/false);
  }
  mesh.shape = std::make_unique<btBvhTriangleMeshShape>(mesh.triangles.get(), true, true);
  // x-y grid for vertical rays: about two triangles' footprint per cell, at most 1024^2 cells.
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (const auto& t : triangles) {
    std::array<Eigen::Vector3d, 3> tri{vertices_W[t[0]], vertices_W[t[1]], vertices_W[t[2]]};
    for (const auto& v : tri) {
      x0 = std::min(x0, v.x());
      y0 = std::min(y0, v.y());
      x1 = std::max(x1, v.x());
      y1 = std::max(y1, v.y());
    }
    mesh.tris.push_back(tri);
  }
  const double w = std::max(x1 - x0, 1e-6), h = std::max(y1 - y0, 1e-6);
  double cell = std::sqrt(w * h / static_cast<double>(triangles.size()));
  cell = std::max({cell, w / 1024, h / 1024, 1e-4});
  struct CellRange {
    int i0, i1, j0, j1;
  };
  auto cells_of = [&](const std::array<Eigen::Vector3d, 3>& tri) {
    double a0 = 1e300, b0 = 1e300, a1 = -1e300, b1 = -1e300;
    for (const auto& v : tri) {
      a0 = std::min(a0, v.x());
      b0 = std::min(b0, v.y());
      a1 = std::max(a1, v.x());
      b1 = std::max(b1, v.y());
    }
    return CellRange{std::clamp(static_cast<int>(std::floor((a0 - x0) / cell)), 0, mesh.nx - 1),
                     std::clamp(static_cast<int>(std::floor((a1 - x0) / cell)), 0, mesh.nx - 1),
                     std::clamp(static_cast<int>(std::floor((b0 - y0) / cell)), 0, mesh.ny - 1),
                     std::clamp(static_cast<int>(std::floor((b1 - y0) / cell)), 0, mesh.ny - 1)};
  };
  // Triangles much larger than a cell (a mesh of floor-spanning triangles) would list each one in
  // millions of cells: coarsen the grid until the lists fit in kMaxGridEntries.
  for (;;) {
    mesh.nx = static_cast<int>(std::floor(w / cell)) + 1;
    mesh.ny = static_cast<int>(std::floor(h / cell)) + 1;
    std::uint64_t entries = 0;
    for (const auto& tri : mesh.tris) {
      const CellRange r = cells_of(tri);
      entries +=
          static_cast<std::uint64_t>(r.i1 - r.i0 + 1) * static_cast<std::uint64_t>(r.j1 - r.j0 + 1);
    }
    if (entries <= kMaxGridEntries || (mesh.nx == 1 && mesh.ny == 1)) break;
    cell *= 2;
  }
  mesh.cell_m = cell;
  mesh.grid_x0 = x0;
  mesh.grid_y0 = y0;
  const std::size_t ncell = static_cast<std::size_t>(mesh.nx) * static_cast<std::size_t>(mesh.ny);
  std::vector<std::uint32_t> count(ncell + 1, 0);
  auto for_cells = [&](const std::array<Eigen::Vector3d, 3>& tri, auto&& fn) {
    const CellRange r = cells_of(tri);
    for (int j = r.j0; j <= r.j1; ++j) {
      for (int i = r.i0; i <= r.i1; ++i) fn(static_cast<std::size_t>(j) * mesh.nx + i);
    }
  };
  for (const auto& tri : mesh.tris) for_cells(tri, [&](std::size_t c) { ++count[c + 1]; });
  for (std::size_t c = 0; c < ncell; ++c) count[c + 1] += count[c];
  mesh.cell_start = count;
  mesh.cell_tris.resize(count[ncell]);
  std::vector<std::uint32_t> fill(count.begin(), count.end() - 1);
  for (std::size_t k = 0; k < mesh.tris.size(); ++k) {
    for_cells(mesh.tris[k],
              [&](std::size_t c) { mesh.cell_tris[fill[c]++] = static_cast<std::uint32_t>(k); });
  }
  mesh.object = std::make_unique<btCollisionObject>();
  mesh.object->setCollisionShape(mesh.shape.get());
  mesh.object->setUserIndex(static_cast<int>(meshes_.size()));
  world_->addCollisionObject(mesh.object.get());
  world_->updateAabbs();
  triangle_count_ += triangles.size();
  meshes_.push_back(std::move(mesh));
}

void Terrain::AddMesh(const std::string& path, const MeshOptions& options) {
  if (!std::filesystem::exists(path)) {
    throw std::invalid_argument(fmt::format("{}: mesh: file not found", path));
  }
  if (!(std::isfinite(options.scale) && options.scale > 0)) {
    throw std::invalid_argument(
        fmt::format("{}: scale ({}) must be finite and > 0", path, options.scale));
  }
  if (options.up_axis != 'y' && options.up_axis != 'z') {
    throw std::invalid_argument(
        fmt::format("{}: up_axis ('{}') must be 'y' or 'z'", path, options.up_axis));
  }
  Assimp::Importer importer;
  const aiScene* scene =
      importer.ReadFile(path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                  aiProcess_PreTransformVertices);
  if (scene == nullptr || scene->mRootNode == nullptr) {
    throw std::invalid_argument(
        fmt::format("{}: mesh: cannot be read: {}", path, importer.GetErrorString()));
  }
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    const int base = static_cast<int>(vertices.size());
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      Eigen::Vector3d q(p.x, p.y, p.z);
      if (!q.allFinite()) {
        throw std::invalid_argument(
            fmt::format("{}: mesh {}: vertex {} is not finite", path, m, v));
      }
      q *= options.scale;
      // y-up files: (x, y, z) -> (x, -z, y) keeps right-handedness with z up.
      if (options.up_axis == 'y') q = Eigen::Vector3d(q.x(), -q.z(), q.y());
      vertices.push_back(q + options.offset_W);
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines from the importer
      triangles.push_back({base + static_cast<int>(face.mIndices[0]),
                           base + static_cast<int>(face.mIndices[1]),
                           base + static_cast<int>(face.mIndices[2])});
    }
  }
  AddTriangles(vertices, triangles, options.friction, path);
}

bool Terrain::GridRaycast(const Mesh& mesh, const Eigen::Vector3d& from, const Eigen::Vector3d& dir,
                          double max_distance, double* t_out, Eigen::Vector3d* normal) noexcept {
  const Eigen::Vector3d to = from + dir * max_distance;
  const double inv = 1.0 / mesh.cell_m;
  const int i0 = static_cast<int>(std::floor((std::min(from.x(), to.x()) - mesh.grid_x0) * inv));
  const int i1 = static_cast<int>(std::floor((std::max(from.x(), to.x()) - mesh.grid_x0) * inv));
  const int j0 = static_cast<int>(std::floor((std::min(from.y(), to.y()) - mesh.grid_y0) * inv));
  const int j1 = static_cast<int>(std::floor((std::max(from.y(), to.y()) - mesh.grid_y0) * inv));
  bool found = false;
  double best = max_distance;
  for (int j = std::max(j0, 0); j <= std::min(j1, mesh.ny - 1); ++j) {
    for (int i = std::max(i0, 0); i <= std::min(i1, mesh.nx - 1); ++i) {
      const std::size_t c = static_cast<std::size_t>(j) * mesh.nx + i;
      for (std::uint32_t k = mesh.cell_start[c]; k < mesh.cell_start[c + 1]; ++k) {
        const auto& tri = mesh.tris[mesh.cell_tris[k]];
        // Moller-Trumbore, two-sided, edges inclusive (a shared edge is never missed).
        const Eigen::Vector3d e1 = tri[1] - tri[0];
        const Eigen::Vector3d e2 = tri[2] - tri[0];
        const Eigen::Vector3d p = dir.cross(e2);
        const double det = e1.dot(p);
        if (std::abs(det) < 1e-15) continue;
        const double inv_det = 1.0 / det;
        const Eigen::Vector3d s = from - tri[0];
        const double u = s.dot(p) * inv_det;
        if (u < -1e-12 || u > 1 + 1e-12) continue;
        const Eigen::Vector3d q = s.cross(e1);
        const double v = dir.dot(q) * inv_det;
        if (v < -1e-12 || u + v > 1 + 1e-12) continue;
        const double t = e2.dot(q) * inv_det;
        if (t < 0 || t > best) continue;
        best = t;
        found = true;
        Eigen::Vector3d n = e1.cross(e2).normalized();
        if (n.dot(dir) > 0) n = -n;
        *normal = n;
      }
    }
  }
  *t_out = best;
  return found;
}

void Terrain::AddPatch(const FrictionPatch& patch) {
  const std::string where = fmt::format("patch '{}'", patch.name);
  if (patch.polygon_W.size() < 3) {
    throw std::invalid_argument(fmt::format("{}: polygon: needs at least 3 vertices, has {}", where,
                                            patch.polygon_W.size()));
  }
  for (const auto& v : patch.polygon_W) {
    if (!v.allFinite()) throw std::invalid_argument(where + ": polygon: vertex is not finite");
  }
  ValidateFriction(patch.friction, where);
  PatchBox box{1e300, -1e300, 1e300, -1e300};
  double extent = 0;
  for (const auto& v : patch.polygon_W) {
    box.x_lo = std::min(box.x_lo, v.x());
    box.x_hi = std::max(box.x_hi, v.x());
    box.y_lo = std::min(box.y_lo, v.y());
    box.y_hi = std::max(box.y_hi, v.y());
    extent = std::max({extent, std::abs(v.x()), std::abs(v.y())});
  }
  // The crossing abscissa is off by a few ulps of the coordinates at most; 1e-9 relative is far
  // above that and far below any patch size that matters.
  const double margin = 1e-9 * (1.0 + extent);
  box.x_lo -= margin;
  box.x_hi += margin;
  patches_.push_back(patch);
  patch_boxes_.push_back(box);
  RebuildPatchGrid();
}

void Terrain::RebuildPatchGrid() {
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (const PatchBox& b : patch_boxes_) {
    x0 = std::min(x0, b.x_lo);
    x1 = std::max(x1, b.x_hi);
    y0 = std::min(y0, b.y_lo);
    y1 = std::max(y1, b.y_hi);
  }
  const double cell = std::max({(x1 - x0) / 64, (y1 - y0) / 64, 1e-6});
  patch_x0_ = x0;
  patch_y0_ = y0;
  patch_inv_cell_ = 1.0 / cell;
  const auto index = [&](double v, double v0) {
    return static_cast<int>(std::floor((v - v0) * patch_inv_cell_));
  };
  patch_nx_ = index(x1, x0) + 1;
  patch_ny_ = index(y1, y0) + 1;
  const std::size_t ncell =
      static_cast<std::size_t>(patch_nx_) * static_cast<std::size_t>(patch_ny_);
  std::vector<std::vector<std::uint32_t>> cells(ncell);
  for (std::size_t k = patch_boxes_.size(); k-- > 0;) {  // newest first
    const PatchBox& b = patch_boxes_[k];
    for (int j = index(b.y_lo, y0); j <= index(b.y_hi, y0); ++j) {
      for (int i = index(b.x_lo, x0); i <= index(b.x_hi, x0); ++i) {
        cells[static_cast<std::size_t>(j) * static_cast<std::size_t>(patch_nx_) +
              static_cast<std::size_t>(i)]
            .push_back(static_cast<std::uint32_t>(k));
      }
    }
  }
  patch_cell_start_.assign(1, 0);
  patch_cell_list_.clear();
  for (const auto& c : cells) {
    patch_cell_list_.insert(patch_cell_list_.end(), c.begin(), c.end());
    patch_cell_start_.push_back(static_cast<std::uint32_t>(patch_cell_list_.size()));
  }
}

Friction Terrain::FrictionAt(const Eigen::Vector3d& p, const Friction& base) const noexcept {
  if (patches_.empty()) return base;
  const double x = p.x(), y = p.y();
  const double fi = std::floor((x - patch_x0_) * patch_inv_cell_);
  const double fj = std::floor((y - patch_y0_) * patch_inv_cell_);
  // Outside the grid (or not finite): outside every box.
  if (!(fi >= 0 && fi < patch_nx_ && fj >= 0 && fj < patch_ny_)) return base;
  const std::size_t c = static_cast<std::size_t>(fj) * static_cast<std::size_t>(patch_nx_) +
                        static_cast<std::size_t>(fi);
  for (std::uint32_t n = patch_cell_start_[c]; n < patch_cell_start_[c + 1]; ++n) {
    const std::uint32_t k = patch_cell_list_[n];
    const PatchBox& b = patch_boxes_[k];
    // Outside the box: no crossing toggles (y) or all or none of an even number do (x).
    if (!(y >= b.y_lo && y < b.y_hi && x >= b.x_lo && x <= b.x_hi)) continue;
    if (InsidePolygon(patches_[k].polygon_W, x, y)) return patches_[k].friction;
  }
  return base;
}

bool Terrain::Raycast(const Eigen::Vector3d& from, const Eigen::Vector3d& dir, double max_dist,
                      SurfaceHit* hit) const noexcept {
  bool found = false;
  double best = max_dist;
  for (const Plane& p : planes_) {
    const double denom = p.n.dot(dir);
    if (denom >= -1e-12) continue;  // parallel or from below
    const double t = (p.d - p.n.dot(from)) / denom;
    if (t < 0 || t > best) continue;
    best = t;
    found = true;
    hit->distance_m = t;
    hit->point_W = from + t * dir;
    hit->normal_W = p.n;
    hit->friction = p.friction;
  }
  if (!meshes_.empty()) {
    // Straight to each mesh's BVH (static meshes have identity transforms, vertices in W): no
    // broadphase pass, no collision-object callback.
    const btVector3 a = ToBt(from);
    const btVector3 b = ToBt(from + dir * best);
    const btVector3 side = ToBt(dir.unitOrthogonal() * 5e-5);
    for (std::size_t m = 0; m < meshes_.size(); ++m) {
      if (std::abs(dir.z()) > 0.7) {
        double t = 0;
        Eigen::Vector3d n;
        if (GridRaycast(meshes_[m], from, dir, best, &t, &n) && (!found || t < hit->distance_m)) {
          found = true;
          hit->distance_m = t;
          hit->point_W = from + t * dir;
          hit->normal_W = n;
          hit->friction = meshes_[m].friction;
        }
        continue;
      }
      ClosestTriangleRay cb(a, b);
      meshes_[m].shape->performRaycast(&cb, a, b);
      if (!cb.hit) {
        // A ray along a shared triangle edge can slip through in single precision; look again
        // 50 um to the side before calling it a gap.
        cb = ClosestTriangleRay(a + side, b + side);
        meshes_[m].shape->performRaycast(&cb, a + side, b + side);
      }
      if (!cb.hit) continue;
      const double t = best * cb.m_hitFraction;
      if (found && t >= hit->distance_m) continue;
      found = true;
      hit->distance_m = t;
      hit->point_W = from + t * dir;
      Eigen::Vector3d n = ToEigen(cb.normal).normalized();
      if (n.dot(dir) > 0) n = -n;  // facing the ray origin
      hit->normal_W = n;
      hit->friction = meshes_[m].friction;
    }
  }
  if (found && !patches_.empty()) hit->friction = FrictionAt(hit->point_W, hit->friction);
  return found;
}

}  // namespace wheelhil::emulator

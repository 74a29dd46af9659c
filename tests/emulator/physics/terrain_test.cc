// Terrain: analytic planes, meshes through assimp in four formats with scale/up-axis options,
// friction patches, and clear errors for missing or malformed meshes.

#include "emulator/physics/terrain.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/emulator/physics/physics_test_util.h"

namespace wheelhil::emulator {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using testing::SourcePath;
using ::testing::ThrowsMessage;

TEST(TerrainMesh, PlaneRaycast) {
  Terrain t;
  t.AddPlane(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, 0, 0.1), Friction{0.8, 0.7});
  SurfaceHit hit;
  ASSERT_TRUE(t.Raycast(Eigen::Vector3d(1, 2, 1), -Eigen::Vector3d::UnitZ(), 2.0, &hit));
  EXPECT_NEAR(hit.distance_m, 0.9, 1e-12);
  EXPECT_NEAR(hit.normal_W.z(), 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(hit.friction.mu_peak, 0.8);
  EXPECT_FALSE(t.Raycast(Eigen::Vector3d(1, 2, 1), -Eigen::Vector3d::UnitZ(), 0.5, &hit));
}

TEST(TerrainMesh, MeshesInFourFormats) {
  struct Case {
    const char* file;
    char up;
  };
  for (const Case c : {Case{"meshes/formats/tile.stl", 'z'}, Case{"meshes/formats/tile.ply", 'z'},
                       Case{"meshes/formats/tile.gltf", 'y'}, Case{"meshes/floor_flat.obj", 'z'}}) {
    Terrain t;
    MeshOptions o;
    o.up_axis = c.up;
    o.scale = 2.0;
    o.offset_W = Eigen::Vector3d(0, 0, 0.05);
    t.AddMesh(SourcePath(c.file), o);
    SurfaceHit hit;
    ASSERT_TRUE(t.Raycast(Eigen::Vector3d(0.5, 0.5, 1), -Eigen::Vector3d::UnitZ(), 2.0, &hit))
        << c.file;
    EXPECT_NEAR(hit.point_W.z(), 0.05, 1e-5) << c.file;
    EXPECT_NEAR(hit.normal_W.z(), 1.0, 1e-5) << c.file;
    // Scale 2: the 1 m tiles reach x = 1.9 m.
    EXPECT_TRUE(t.Raycast(Eigen::Vector3d(1.9, 1.9, 1), -Eigen::Vector3d::UnitZ(), 2.0, &hit))
        << c.file;
  }
}

TEST(TerrainMesh, ShippedMeshesHaveTheirFeatures) {
  Terrain bump;
  bump.AddMesh(SourcePath("meshes/bump.obj"), MeshOptions{});
  SurfaceHit hit;
  ASSERT_TRUE(bump.Raycast(Eigen::Vector3d(1.0, 0, 1), -Eigen::Vector3d::UnitZ(), 2, &hit));
  EXPECT_NEAR(hit.point_W.z(), 0.020, 1e-4);
  Terrain ramp;
  ramp.AddMesh(SourcePath("meshes/ramp.obj"), MeshOptions{});
  ASSERT_TRUE(ramp.Raycast(Eigen::Vector3d(2.0, 0, 1), -Eigen::Vector3d::UnitZ(), 2, &hit));
  EXPECT_NEAR(hit.point_W.z(), std::tan(5.0 * M_PI / 180), 1e-4);
  EXPECT_NEAR(std::acos(hit.normal_W.z()), 5.0 * M_PI / 180, 1e-4);
  Terrain door;
  door.AddMesh(SourcePath("meshes/door_threshold.obj"), MeshOptions{});
  ASSERT_TRUE(door.Raycast(Eigen::Vector3d(1.02, 0, 1), -Eigen::Vector3d::UnitZ(), 2, &hit));
  EXPECT_NEAR(hit.point_W.z(), 0.012, 1e-4);
  Terrain tiles;
  tiles.AddMesh(SourcePath("meshes/uneven_tiles.obj"), MeshOptions{});
  double zmin = 1, zmax = -1;
  for (int i = 0; i < 40; ++i) {
    ASSERT_TRUE(tiles.Raycast(Eigen::Vector3d(-1.5 + 0.0743 * i, 0.11, 1),
                              -Eigen::Vector3d::UnitZ(), 2, &hit));
    zmin = std::min(zmin, hit.point_W.z());
    zmax = std::max(zmax, hit.point_W.z());
  }
  EXPECT_GT(zmax - zmin, 5e-4);
  EXPECT_LT(zmax - zmin, 6e-3);
}

TEST(TerrainMesh, MeshRaysOnEdgesVerticesAndSlanted) {
  Terrain t;
  t.AddMesh(SourcePath("meshes/floor_flat.obj"), MeshOptions{});
  SurfaceHit hit;
  // Vertical rays (grid path) exactly through a vertex and along shared edges.
  for (const auto& xy : {Eigen::Vector2d(0.5, 0.5), Eigen::Vector2d(0.5, 0.123),
                         Eigen::Vector2d(0.25, 0.25), Eigen::Vector2d(-2.0, -2.0)}) {
    ASSERT_TRUE(t.Raycast(Eigen::Vector3d(xy.x(), xy.y(), 0.3), -Eigen::Vector3d::UnitZ(), 1, &hit))
        << xy.transpose();
    EXPECT_NEAR(hit.distance_m, 0.3, 1e-12);
  }
  // A slanted ray (Bullet BVH path) at 60 deg from vertical.
  const Eigen::Vector3d dir = Eigen::Vector3d(std::sin(M_PI / 3), 0, -std::cos(M_PI / 3));
  ASSERT_TRUE(t.Raycast(Eigen::Vector3d(0, 0.1, 0.5), dir, 2, &hit));
  EXPECT_NEAR(hit.distance_m, 1.0, 1e-5);
  // Off the mesh: nothing.
  EXPECT_FALSE(t.Raycast(Eigen::Vector3d(3, 0, 0.3), -Eigen::Vector3d::UnitZ(), 1, &hit));
}

TEST(TerrainMesh, PatchOverridesFriction) {
  Terrain t;
  t.AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{0.8, 0.7});
  t.AddPatch(FrictionPatch{"oil", {{0, 0}, {1, 0}, {1, 1}, {0, 1}}, Friction{0.05, 0.04}});
  SurfaceHit hit;
  ASSERT_TRUE(t.Raycast(Eigen::Vector3d(0.5, 0.5, 1), -Eigen::Vector3d::UnitZ(), 2, &hit));
  EXPECT_DOUBLE_EQ(hit.friction.mu_peak, 0.05);
  ASSERT_TRUE(t.Raycast(Eigen::Vector3d(1.5, 0.5, 1), -Eigen::Vector3d::UnitZ(), 2, &hit));
  EXPECT_DOUBLE_EQ(hit.friction.mu_peak, 0.8);
}

// FrictionAt's grid and per-patch boxes must answer exactly like testing every polygon, newest
// first: overlapping, concave and thin patches, points on vertices, edges and box borders.
TEST(TerrainMesh, PatchLookupMatchesTestingEveryPolygon) {
  std::vector<FrictionPatch> patches = {
      {"square", {{0, 0}, {1, 0}, {1, 1}, {0, 1}}, Friction{0.1, 0.1}},
      {"overlap", {{0.5, 0.5}, {2, 0.5}, {2, 2}, {0.5, 2}}, Friction{0.2, 0.2}},
      {"concave", {{3, 0}, {5, 0}, {5, 2}, {4, 0.5}, {3, 2}}, Friction{0.3, 0.3}},
      {"thin", {{-1, -0.001}, {6, -0.001}, {6, 0.001}, {-1, 0.001}}, Friction{0.4, 0.4}},
      {"triangle", {{0.3, 1.7}, {1.1, -0.4}, {1.9, 1.7}}, Friction{0.5, 0.5}},
      {"far", {{100, 100}, {100.1, 100}, {100.1, 100.1}}, Friction{0.6, 0.6}},
  };
  Terrain t;
  for (const auto& p : patches) t.AddPatch(p);
  const auto reference = [&](double x, double y) {
    for (auto it = patches.rbegin(); it != patches.rend(); ++it) {
      bool inside = false;
      const auto& poly = it->polygon_W;
      for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
        const auto& a = poly[i];
        const auto& b = poly[j];
        if ((a.y() > y) != (b.y() > y) &&
            x < (b.x() - a.x()) * (y - a.y()) / (b.y() - a.y()) + a.x()) {
          inside = !inside;
        }
      }
      if (inside) return it->friction.mu_peak;
    }
    return 0.8;
  };
  std::vector<double> xs, ys;
  for (const auto& p : patches) {
    for (const auto& v : p.polygon_W) {
      for (double d : {-1e-12, 0.0, 1e-12}) {
        xs.push_back(v.x() + d);
        ys.push_back(v.y() + d);
      }
    }
  }
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> ux(-2, 7), uy(-1, 3);
  for (int k = 0; k < 200; ++k) {
    xs.push_back(ux(rng));
    ys.push_back(uy(rng));
  }
  int inside = 0;
  for (double x : xs) {
    for (double y : ys) {
      const double want = reference(x, y);
      inside += want != 0.8;
      ASSERT_EQ(t.FrictionAt(Eigen::Vector3d(x, y, 0), Friction{0.8, 0.7}).mu_peak, want)
          << "at (" << x << ", " << y << ")";
    }
  }
  EXPECT_GT(inside, 1000);  // the points do land in patches
  EXPECT_EQ(t.FrictionAt(Eigen::Vector3d(100.05, 100.01, 0), Friction{}).mu_peak, 0.6);
}

TEST(TerrainMesh, ErrorsNameFileAndField) {
  Terrain t;
  EXPECT_THAT([&] { t.AddMesh("/nonexistent/floor.obj", MeshOptions{}); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("/nonexistent/floor.obj"), HasSubstr("not found"))));
  const auto bad = std::filesystem::temp_directory_path() / "wheelhil_bad_mesh.stl";
  {
    std::ofstream out(bad);
    out << "solid x\n facet normal 0 0 1\n outer loop\n vertex 0 0\n";
  }
  EXPECT_THAT([&] { t.AddMesh(bad.string(), MeshOptions{}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(bad.string())));
  std::remove(bad.string().c_str());
  MeshOptions o;
  o.up_axis = 'x';
  EXPECT_THAT([&] { t.AddMesh(SourcePath("meshes/floor_flat.obj"), o); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("up_axis")));
  EXPECT_THAT(
      [&] {
        t.AddPatch(FrictionPatch{"p", {{0, 0}, {1, 0}}, Friction{}});
      },
      ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("'p'"), HasSubstr("polygon"))));
  EXPECT_THAT(
      [&] {
        t.AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{0.5, 0.9});
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("mu_slide")));
}

// 70 000 triangles that each span the whole floor would list every triangle in each of ~10^6 grid
// cells (7 * 10^10 entries, past uint32 counts): the grid coarsens instead, and rays still find
// the highest of the stacked floors.
TEST(TerrainMesh, FloorSpanningTrianglesCoarsenTheGrid) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> tris;
  constexpr int kFloors = 35'000;
  for (int k = 0; k < kFloors; ++k) {
    const double z = 1e-6 * k;
    const int b = static_cast<int>(v.size());
    v.insert(v.end(), {{-5, -5, z}, {5, -5, z}, {5, 5, z}, {-5, 5, z}});
    tris.push_back({b, b + 1, b + 2});
    tris.push_back({b, b + 2, b + 3});
  }
  Terrain t;
  t.AddTriangles(v, tris, Friction{});
  SurfaceHit hit;
  ASSERT_TRUE(t.Raycast(Eigen::Vector3d(1.3, -2.1, 1), -Eigen::Vector3d::UnitZ(), 2.0, &hit));
  EXPECT_NEAR(hit.point_W.z(), 1e-6 * (kFloors - 1), 1e-9);
  EXPECT_EQ(t.triangle_count(), tris.size());
}

TEST(TerrainMesh, NonFiniteVerticesAndTooManyTrianglesAreRefused) {
  Terrain t;
  const std::vector<Eigen::Vector3d> v{{0, 0, 0}, {1, 0, 0}, {0, std::nan(""), 0}};
  EXPECT_THAT(
      [&] {
        t.AddTriangles(v, {{0, 1, 2}}, Friction{}, "floor.obj");
      },
      ThrowsMessage<std::invalid_argument>(
          AllOf(HasSubstr("floor.obj"), HasSubstr("vertex 2 is not finite"))));
  const std::vector<std::array<int, 3>> many(Terrain::kMaxTriangles + 1, {0, 1, 1});
  EXPECT_THAT(
      [&] {
        t.AddTriangles({{0, 0, 0}, {1, 0, 0}}, many, Friction{}, "big.obj");
      },
      ThrowsMessage<std::invalid_argument>(
          AllOf(HasSubstr("big.obj"), HasSubstr("at most 4000000"))));
}

}  // namespace
}  // namespace wheelhil::emulator

// Coal distances of many (robot geometry, obstacle) sites in one call, for
// mbplan.multibody.coal_pass. The shapes are the ones the Python coal objects hold (their
// addresses); each site's request policy is that of mbplan.multibody.collision.signed_distances.
#include <coal/collision_object.h>
#include <coal/distance.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>

namespace {

using Geometry = coal::CollisionGeometry;

coal::Transform3s pose(const double* R, const double* t) {
  coal::Matrix3s rotation;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rotation(i, j) = R[3 * i + j];  // row-major (numpy)
  return coal::Transform3s(rotation, coal::Vec3s(t[0], t[1], t[2]));
}

coal::DistanceRequest request(double gjk_tolerance, double epa_tolerance) {
  coal::DistanceRequest r;
  r.gjk_tolerance = gjk_tolerance;
  r.epa_tolerance = epa_tolerance;
  return r;
}

struct Found {
  double distance;
  coal::DistanceResult result;
};

// Coal's distance with its result; false where GJK/EPA failed (coal reports +-DBL_MAX).
bool attempt(const Geometry* a, const coal::Transform3s& ta, const Geometry* b,
             const coal::Transform3s& tb, const coal::DistanceRequest& r, double failed,
             Found& out) {
  out.result = coal::DistanceResult();
  out.distance = coal::distance(a, ta, b, tb, r, out.result);
  return std::fabs(out.distance) < failed;
}

// One site (see mbplan_coal_distances); false where it failed.
bool site(int64_t robot, int64_t obstacle, const int32_t* node_type, uint8_t checked,
          const double* robot_R, const double* robot_t, const double* obstacle_R,
          const double* obstacle_t, const coal::DistanceRequest& polytope,
          const coal::DistanceRequest& tight, const coal::DistanceRequest& check,
          const coal::DistanceRequest& fallback, double cross_check, double failed,
          double& distance, double* normal, double* point) {
  const Geometry* a = reinterpret_cast<const Geometry*>(robot);
  const Geometry* b = reinterpret_cast<const Geometry*>(obstacle);
  try {
    if (static_cast<int>(a->getNodeType()) != node_type[0] ||
        static_cast<int>(b->getNodeType()) != node_type[1])
      return false;
    const coal::Transform3s ta = pose(robot_R, robot_t), tb = pose(obstacle_R, obstacle_t);
    Found first, second;
    const Found* answer = nullptr;
    if (checked) {
      const bool has_first = attempt(a, ta, b, tb, tight, failed, first);
      const bool has_second = attempt(a, ta, b, tb, check, failed, second);
      if (has_first && has_second)
        answer = std::fabs(first.distance - second.distance) > cross_check ? &second : &first;
      else if (has_first)
        answer = &first;
      else if (has_second)
        answer = &second;
    } else if (attempt(a, ta, b, tb, polytope, failed, first)) {
      answer = &first;
    }
    if (answer == nullptr) {
      if (!attempt(a, ta, b, tb, fallback, failed, first)) return false;
      answer = &first;
    }
    distance = answer->distance;
    for (int i = 0; i < 3; ++i) {
      normal[i] = answer->result.normal[i];
      point[i] = answer->result.nearest_points[0][i];
    }
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

// Site s: robot geometry robot[s] at (robot_R[s], robot_t[s]) against obstacle obstacle[s] at
// (obstacle_R[s], obstacle_t[s]); node_type[2s], node_type[2s+1] are the types the caller
// expects of the two. A checked site (curved or mesh shape) asks at tolerance[1] and
// tolerance[2] and keeps the second where they differ by more than tolerance[4]; other sites
// ask once at tolerance[0]; coal's default request if every attempt failed. tolerance[3]:
// EPA's, tolerance[5]: the magnitude from which coal's answer is a failure.
// Returns -1, or the first site that failed (a type mismatch, no answer, a coal exception),
// where the caller falls back to its own loop. Sites are independent: with OpenMP they are
// shared among threads, each writing only its own outputs (the same answers in any order).
extern "C" long long mbplan_coal_distances(long long S, const int64_t* robot,
                                           const int64_t* obstacle, const int32_t* node_type,
                                           const uint8_t* checked, const double* robot_R,
                                           const double* robot_t, const double* obstacle_R,
                                           const double* obstacle_t, const double* tolerance,
                                           double* distance, double* normal, double* point) {
  const coal::DistanceRequest polytope = request(tolerance[0], tolerance[3]);
  const coal::DistanceRequest tight = request(tolerance[1], tolerance[3]);
  const coal::DistanceRequest check = request(tolerance[2], tolerance[3]);
  const coal::DistanceRequest fallback;
  const double cross_check = tolerance[4], failed = tolerance[5];
  long long first_failure = S;
#pragma omp parallel for schedule(dynamic, 32) reduction(min : first_failure) if (S > 256)
  for (long long s = 0; s < S; ++s) {
    if (!site(robot[s], obstacle[s], node_type + 2 * s, checked[s], robot_R + 9 * s,
              robot_t + 3 * s, obstacle_R + 9 * s, obstacle_t + 3 * s, polytope, tight, check,
              fallback, cross_check, failed, distance[s], normal + 3 * s, point + 3 * s))
      first_failure = std::min(first_failure, s);
  }
  return first_failure == S ? -1 : first_failure;
}

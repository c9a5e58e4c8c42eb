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

// from_boxes: GJK starts from the shapes' bounding-box centres (as collision.py's polytope
// request).
coal::DistanceRequest request(double gjk_tolerance, double epa_tolerance, bool from_boxes) {
  coal::DistanceRequest r;
  r.gjk_tolerance = gjk_tolerance;
  r.epa_tolerance = epa_tolerance;
  if (from_boxes) r.gjk_initial_guess = coal::GJKInitialGuess::BoundingVolumeGuess;
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
bool site(const Geometry* a, const coal::Transform3s& ta, const Geometry* b,
          const coal::Transform3s& tb, const int32_t* node_type, uint8_t checked,
          const coal::DistanceRequest& polytope, const coal::DistanceRequest& tight,
          const coal::DistanceRequest& check, const coal::DistanceRequest& fallback,
          double cross_check, double failed, double& distance, double* normal, double* point) {
  try {
    if (static_cast<int>(a->getNodeType()) != node_type[0] ||
        static_cast<int>(b->getNodeType()) != node_type[1])
      return false;
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

// The lower bound of a site's distance (mbplan.multibody.collision.lower_bounds): the larger of
// the gaps between one shape's bounding sphere (around its local AABB: center c, half
// extents h) and the other's AABB.
double lower_bound(const coal::Transform3s& ta, const double* box_a, const coal::Transform3s& tb,
                   const double* box_b) {
  const coal::Vec3s ca(box_a[0], box_a[1], box_a[2]), ha(box_a[3], box_a[4], box_a[5]);
  const coal::Vec3s cb(box_b[0], box_b[1], box_b[2]), hb(box_b[3], box_b[4], box_b[5]);
  const coal::Vec3s a_in_b = tb.inverseTransform(ta.transform(ca)) - cb;
  const coal::Vec3s b_in_a = ta.inverseTransform(tb.transform(cb)) - ca;
  const double gap_a = (a_in_b.cwiseAbs() - hb).cwiseMax(0.0).norm() - ha.norm();
  const double gap_b = (b_in_a.cwiseAbs() - ha).cwiseMax(0.0).norm() - hb.norm();
  return std::max(gap_a, gap_b);
}

}  // namespace

// Site s couples pair p = pair[s]: robot geometry robot[p] at (robot_R[s], robot_t[s]) with
// obstacle obstacle[p] at (obstacle_R[p], obstacle_t[p]); node_type[2p], node_type[2p+1] are
// the types the caller expects of the two, robot_box[p], obstacle_box[p] their local AABBs
// (center, half extents). The distance is capped at cap[s] (above it: the cap, a zero normal
// and the robot geometry's origin as witness point), and a site whose lower bound exceeds the
// cap is not sent to coal. A checked pair (curved or mesh shape) asks at tolerance[1] and
// tolerance[2] and keeps the second where they differ by more than tolerance[4]; other pairs
// ask once at tolerance[0]; coal's default request if every attempt failed. tolerance[3]:
// EPA's, tolerance[5]: the magnitude from which coal's answer is a failure.
// Returns -1, or the first site that failed (a type mismatch, no answer, a coal exception),
// where the caller falls back to its own loop; sent counts the sites sent to coal. Sites are
// independent: with OpenMP they are shared among threads, each writing only its own outputs
// (the same answers in any order).
extern "C" long long mbplan_coal_distances(
    long long S, const int64_t* pair, const int64_t* robot, const int64_t* obstacle,
    const int32_t* node_type, const uint8_t* checked, const double* robot_box,
    const double* obstacle_box, const double* obstacle_R, const double* obstacle_t,
    const double* robot_R, const double* robot_t, const double* cap, const double* tolerance,
    double* distance, double* normal, double* point, long long* sent) {
  const coal::DistanceRequest polytope = request(tolerance[0], tolerance[3], true);
  const coal::DistanceRequest tight = request(tolerance[1], tolerance[3], false);
  const coal::DistanceRequest check = request(tolerance[2], tolerance[3], false);
  const coal::DistanceRequest fallback;
  const double cross_check = tolerance[4], failed = tolerance[5];
  long long first_failure = S, asked = 0;
#pragma omp parallel for schedule(dynamic, 32) reduction(min : first_failure) \
    reduction(+ : asked) if (S > 256)
  for (long long s = 0; s < S; ++s) {
    const int64_t p = pair[s];
    const coal::Transform3s ta = pose(robot_R + 9 * s, robot_t + 3 * s);
    const coal::Transform3s tb = pose(obstacle_R + 9 * p, obstacle_t + 3 * p);
    double d = cap[s];
    double n[3] = {0.0, 0.0, 0.0};
    double w[3] = {robot_t[3 * s], robot_t[3 * s + 1], robot_t[3 * s + 2]};
    if (lower_bound(ta, robot_box + 6 * p, tb, obstacle_box + 6 * p) <= cap[s]) {
      ++asked;
      double found, found_n[3], found_w[3];
      if (!site(reinterpret_cast<const Geometry*>(robot[p]), ta,
                reinterpret_cast<const Geometry*>(obstacle[p]), tb, node_type + 2 * p,
                checked[p], polytope, tight, check, fallback, cross_check, failed, found,
                found_n, found_w)) {
        first_failure = std::min(first_failure, s);
        continue;
      }
      if (found < cap[s]) {
        d = found;
        std::copy(found_n, found_n + 3, n);
        std::copy(found_w, found_w + 3, w);
      }
    }
    distance[s] = d;
    std::copy(n, n + 3, normal + 3 * s);
    std::copy(w, w + 3, point + 3 * s);
  }
  *sent = asked;
  return first_failure == S ? -1 : first_failure;
}

// What colmap's database says about each photo: how many features it found and how well the
// photo matched the others. Private to the sfm layer; used to say why a photo was not placed
// and whether matching again can help it.
#pragma once

#include <filesystem>
#include <map>
#include <string>

#include "desplat/sfm/sfm.hpp"

namespace desplat::sfm {

struct MatchEvidence {
  int features = 0;            // SIFT keypoints colmap extracted
  int matched_photos = 0;      // photos it shares a geometrically verified pair with
  int placeable_partners = 0;  // of those, pairs with at least kPlaceableInliers inliers
  int best_inliers = 0;        // the largest verified match count among those pairs
};

// Fewer than kPlaceableMinPartners partners with kPlaceableInliers inliers (sfm.hpp): matching
// again could help such a photo; a photo with more was matched, and only the mapper refused it.
bool lacks_matches(const MatchEvidence& evidence);

// Per image name (as colmap stores it: relative to images/). Photos colmap never added to the
// database are absent. Throws std::runtime_error naming the file when it cannot be read as a
// colmap database.
std::map<std::string, MatchEvidence> read_match_evidence(const std::filesystem::path& database);

// Deletes every match and verified pair from a colmap database, keeping images, cameras and
// features, so a matcher run on it matches every pair again (it skips pairs it has). Throws
// std::runtime_error naming the file when that fails.
void forget_matches(const std::filesystem::path& database);

}  // namespace desplat::sfm

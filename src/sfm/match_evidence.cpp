// Reads colmap 3.8's database.db (SQLite): images, keypoints, two_view_geometries; clears matches.
#include "sfm/match_evidence.hpp"

#include <cstdint>
#include <stdexcept>

#include "sfm/colmap_database.hpp"

namespace desplat::sfm {

std::map<std::string, MatchEvidence> read_match_evidence(const std::filesystem::path& database) {
  const ColmapDatabase db(database, SQLITE_OPEN_READONLY);
  std::map<int64_t, std::string> name_of;
  std::map<std::string, MatchEvidence> evidence;
  db.query("SELECT image_id, name FROM images", [&](sqlite3_stmt* s) {
    const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(s, 1));
    name_of[sqlite3_column_int64(s, 0)] = text ? text : "";
    evidence[name_of[sqlite3_column_int64(s, 0)]];
  });
  db.query("SELECT image_id, rows FROM keypoints", [&](sqlite3_stmt* s) {
    if (const auto it = name_of.find(sqlite3_column_int64(s, 0)); it != name_of.end())
      evidence[it->second].features = sqlite3_column_int(s, 1);
  });
  // Verified pairs: rows = inlier matches (0 when verification failed).
  db.query("SELECT pair_id, rows FROM two_view_geometries WHERE rows > 0", [&](sqlite3_stmt* s) {
    const int64_t pair = sqlite3_column_int64(s, 0);
    const int inliers = sqlite3_column_int(s, 1);
    for (const int64_t id : {pair / kColmapMaxImageId, pair % kColmapMaxImageId})
      if (const auto it = name_of.find(id); it != name_of.end()) {
        MatchEvidence& e = evidence[it->second];
        ++e.matched_photos;
        if (inliers >= kPlaceableInliers) ++e.placeable_partners;
        e.best_inliers = std::max(e.best_inliers, inliers);
      }
  });
  return evidence;
}

bool lacks_matches(const MatchEvidence& e) { return e.placeable_partners < kPlaceableMinPartners; }

void forget_matches(const std::filesystem::path& database) {
  const ColmapDatabase db(database, SQLITE_OPEN_READWRITE);
  char* error = nullptr;
  if (sqlite3_exec(db.handle(), "DELETE FROM matches; DELETE FROM two_view_geometries;", nullptr, nullptr, &error) !=
      SQLITE_OK) {
    const std::string why = error ? error : "unknown error";
    sqlite3_free(error);
    throw std::runtime_error(database.string() + ": cannot clear colmap's matches: " + why);
  }
}

}  // namespace desplat::sfm

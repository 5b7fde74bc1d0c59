// Reads colmap 3.8's database.db (SQLite): images, keypoints, two_view_geometries; clears matches.
#include "sfm/match_evidence.hpp"

#include <sqlite3.h>

#include <cstdint>
#include <memory>
#include <stdexcept>

namespace desplat::sfm {
namespace {

// colmap's pair id: image_id1 · 2147483647 + image_id2 with image_id1 < image_id2.
constexpr int64_t kMaxImageId = 2147483647;

struct Closer {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
  void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};

std::unique_ptr<sqlite3, Closer> open_database(const std::filesystem::path& database, int flags) {
  sqlite3* raw = nullptr;
  if (sqlite3_open_v2(database.c_str(), &raw, flags, nullptr) != SQLITE_OK) {
    const std::string why = raw ? sqlite3_errmsg(raw) : "out of memory";
    sqlite3_close(raw);
    throw std::runtime_error(database.string() + ": cannot open colmap's database: " + why);
  }
  return std::unique_ptr<sqlite3, Closer>(raw);
}

}  // namespace

std::map<std::string, MatchEvidence> read_match_evidence(const std::filesystem::path& database) {
  const auto db = open_database(database, SQLITE_OPEN_READONLY);
  auto query = [&](const char* sql, auto&& on_row) {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(db.get(), sql, -1, &stmt, nullptr) != SQLITE_OK)
      throw std::runtime_error(database.string() + ": not a colmap database (" + sqlite3_errmsg(db.get()) + ")");
    const std::unique_ptr<sqlite3_stmt, Closer> owned(stmt);
    int rc;
    while ((rc = sqlite3_step(stmt)) == SQLITE_ROW) on_row(stmt);
    if (rc != SQLITE_DONE) throw std::runtime_error(database.string() + ": " + sqlite3_errmsg(db.get()));
  };
  std::map<int64_t, std::string> name_of;
  std::map<std::string, MatchEvidence> evidence;
  query("SELECT image_id, name FROM images", [&](sqlite3_stmt* s) {
    const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(s, 1));
    name_of[sqlite3_column_int64(s, 0)] = text ? text : "";
    evidence[name_of[sqlite3_column_int64(s, 0)]];
  });
  query("SELECT image_id, rows FROM keypoints", [&](sqlite3_stmt* s) {
    if (const auto it = name_of.find(sqlite3_column_int64(s, 0)); it != name_of.end())
      evidence[it->second].features = sqlite3_column_int(s, 1);
  });
  // Verified pairs: rows = inlier matches (0 when verification failed).
  query("SELECT pair_id, rows FROM two_view_geometries WHERE rows > 0", [&](sqlite3_stmt* s) {
    const int64_t pair = sqlite3_column_int64(s, 0);
    const int inliers = sqlite3_column_int(s, 1);
    for (const int64_t id : {pair / kMaxImageId, pair % kMaxImageId})
      if (const auto it = name_of.find(id); it != name_of.end()) {
        MatchEvidence& e = evidence[it->second];
        ++e.matched_photos;
        e.best_inliers = std::max(e.best_inliers, inliers);
      }
  });
  return evidence;
}

void forget_matches(const std::filesystem::path& database) {
  const auto db = open_database(database, SQLITE_OPEN_READWRITE);
  char* error = nullptr;
  if (sqlite3_exec(db.get(), "DELETE FROM matches; DELETE FROM two_view_geometries;", nullptr, nullptr, &error) !=
      SQLITE_OK) {
    const std::string why = error ? error : "unknown error";
    sqlite3_free(error);
    throw std::runtime_error(database.string() + ": cannot clear colmap's matches: " + why);
  }
}

}  // namespace desplat::sfm

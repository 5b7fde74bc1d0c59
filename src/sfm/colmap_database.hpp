// Read access to colmap's database.db (SQLite) for the sfm layer's readers: one open handle and
// a query that calls back once per row. Private to the sfm layer.
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

namespace desplat::sfm {

// colmap's pair id: image_id1 · 2147483647 + image_id2 with image_id1 < image_id2.
inline constexpr int64_t kColmapMaxImageId = 2147483647;

class ColmapDatabase {
 public:
  // Throws std::runtime_error naming the file when it cannot be opened with `flags`.
  ColmapDatabase(const std::filesystem::path& file, int flags) : file_(file) {
    sqlite3* raw = nullptr;
    if (sqlite3_open_v2(file.c_str(), &raw, flags, nullptr) != SQLITE_OK) {
      const std::string why = raw ? sqlite3_errmsg(raw) : "out of memory";
      sqlite3_close(raw);
      throw std::runtime_error(file.string() + ": cannot open colmap's database: " + why);
    }
    db_.reset(raw);
  }

  // Runs `sql`, calling on_row(stmt) for each row. Throws std::runtime_error naming the file when
  // the statement does not compile (a table or column missing: not a colmap database) or fails.
  template <class OnRow>
  void query(const char* sql, OnRow&& on_row) const {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(db_.get(), sql, -1, &stmt, nullptr) != SQLITE_OK)
      throw std::runtime_error(file_.string() + ": not a colmap database (" + sqlite3_errmsg(db_.get()) + ")");
    const std::unique_ptr<sqlite3_stmt, Closer> owned(stmt);
    int rc;
    while ((rc = sqlite3_step(stmt)) == SQLITE_ROW) on_row(stmt);
    if (rc != SQLITE_DONE) throw std::runtime_error(file_.string() + ": " + sqlite3_errmsg(db_.get()));
  }

  sqlite3* handle() const { return db_.get(); }
  const std::filesystem::path& file() const { return file_; }

 private:
  struct Closer {
    void operator()(sqlite3* db) const { sqlite3_close(db); }
    void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
  };
  std::filesystem::path file_;
  std::unique_ptr<sqlite3, Closer> db_;
};

}  // namespace desplat::sfm

// Train/test split rules (splits.hpp) on synthetic name lists whose answers are worked out
// by hand in each test, plus every error case.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>

#include "desplat/io/splits.hpp"

namespace fs = std::filesystem;
using namespace desplat;
using R = ViewRole;

namespace {

struct TempFile {
  fs::path path;
  TempFile(const std::string& name, const std::string& text) {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("desplat_test_splits_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + "_" + name);
    std::ofstream(path) << text;
  }
  ~TempFile() { fs::remove(path); }
};

std::string error_of(const std::vector<std::string>& names, const SplitOptions& o) {
  try {
    assign_split(names, o);
  } catch (const SplitError& e) {
    return e.what();
  }
  return "no error";
}

#define EXPECT_CONTAINS(haystack, needle) EXPECT_NE((haystack).find(needle), std::string::npos) << (haystack)

SplitOptions rule(SplitRule r) {
  SplitOptions o;
  o.rule = r;
  return o;
}

}  // namespace

TEST(Splits, EveryEighthByNameIsHeldOut) {
  // 10 names given out of order: sorted they are a00..a09, so a00 and a08 are test views.
  const std::vector<std::string> names = {"a05", "a00", "a09", "a03", "a08", "a01", "a02", "a04", "a06", "a07"};
  const auto roles = assign_split(names, {});
  for (size_t i = 0; i < names.size(); ++i)
    EXPECT_EQ(roles[i], names[i] == "a00" || names[i] == "a08" ? R::Test : R::Train) << names[i];
  SplitOptions every3;
  every3.every_nth = 3;  // sorted positions 0, 3, 6, 9 -> a00, a03, a06, a09
  const auto r3 = assign_split(names, every3);
  for (size_t i = 0; i < names.size(); ++i) {
    const bool test = names[i] == "a00" || names[i] == "a03" || names[i] == "a06" || names[i] == "a09";
    EXPECT_EQ(r3[i], test ? R::Test : R::Train) << names[i];
  }
  // Byte order, not numeric order: "img10" sorts before "img2".
  EXPECT_EQ(assign_split({"img2", "img10"}, every3), (std::vector<R>{R::Train, R::Test}));
}

TEST(Splits, AllTrain) {
  EXPECT_EQ(assign_split({"b", "a"}, rule(SplitRule::AllTrain)), (std::vector<R>{R::Train, R::Train}));
}

TEST(Splits, NameLists) {
  const std::vector<std::string> names = {"a.jpg", "b.jpg", "c.jpg", "sub/d.jpg"};
  TempFile test_list("test.txt", "# held out\n  b.jpg \r\n\nsub/d.jpg\n");
  TempFile train_list("train.txt", "a.jpg\n");
  SplitOptions o = rule(SplitRule::NameLists);
  o.test_list = test_list.path;  // only a test list: the rest train
  EXPECT_EQ(assign_split(names, o), (std::vector<R>{R::Train, R::Test, R::Train, R::Test}));
  o.train_list = train_list.path;  // both: the rest unused
  EXPECT_EQ(assign_split(names, o), (std::vector<R>{R::Train, R::Test, R::Unused, R::Test}));
  o.test_list.clear();  // only a train list: the rest test
  EXPECT_EQ(assign_split(names, o), (std::vector<R>{R::Train, R::Test, R::Test, R::Test}));
}

TEST(Splits, NameListErrors) {
  const std::vector<std::string> names = {"a.jpg", "b.jpg"};
  SplitOptions o = rule(SplitRule::NameLists);
  EXPECT_CONTAINS(error_of(names, o), "needs a train list, a test list or both");
  TempFile unknown("unknown.txt", "a.jpg\nz.jpg\n");
  o.test_list = unknown.path;
  EXPECT_CONTAINS(error_of(names, o), unknown.path.string() + ":2: 'z.jpg' is not a registered image");
  TempFile both_train("train.txt", "a.jpg\n"), both_test("test.txt", "a.jpg\n");
  o.train_list = both_train.path;
  o.test_list = both_test.path;
  EXPECT_CONTAINS(error_of(names, o), both_test.path.string() + ":1: 'a.jpg' is in both the train and the test list");
  TempFile everything("test.txt", "a.jpg\nb.jpg\n");
  o.train_list.clear();
  o.test_list = everything.path;
  EXPECT_CONTAINS(error_of(names, o), "leaves no training view among 2 images");
  o.test_list = "/nonexistent/test.txt";
  EXPECT_CONTAINS(error_of(names, o), "/nonexistent/test.txt: cannot read the split file");
}

TEST(Splits, RobustNeRFTrainsOnClutterAndTestsOnExtra) {
  const std::vector<std::string> names = {"1extra000.JPG",   "2clutter000.JPG", "0clean000.JPG",
                                          "2clutter001.JPG", "1extra001.JPG",   "0clean001.JPG"};
  EXPECT_EQ(assign_split(names, rule(SplitRule::RobustNeRF)),
            (std::vector<R>{R::Test, R::Train, R::Unused, R::Train, R::Test, R::Unused}));
  EXPECT_CONTAINS(error_of({"1extra000.JPG", "photo.JPG"}, rule(SplitRule::RobustNeRF)),
                  "'photo.JPG' must contain exactly one of 'clean', 'clutter', 'extra'");
  EXPECT_CONTAINS(error_of({"clean_clutter.JPG"}, rule(SplitRule::RobustNeRF)), "exactly one of");
  // Only clean and extra images: nothing to train on.
  EXPECT_CONTAINS(error_of({"clean1.JPG", "extra1.JPG"}, rule(SplitRule::RobustNeRF)), "no training view");
}

TEST(Splits, RobustNeRFClutterRatioMixesPairsEvenly) {
  // Five clean/clutter pairs (names out of order), one extra clean view, one clutter view
  // without a clean partner (dropped: pairs are truncated to the shorter list).
  std::vector<std::string> names;
  for (int k = 4; k >= 0; --k) {
    names.push_back("clean" + std::to_string(k) + ".png");
    names.push_back("clutter" + std::to_string(k) + ".png");
  }
  names.push_back("clutter9.png");
  names.push_back("extra0.png");
  const auto role_of = [&](const std::vector<R>& roles, const std::string& name) {
    return roles[size_t(std::find(names.begin(), names.end(), name) - names.begin())];
  };
  SplitOptions o = rule(SplitRule::RobustNeRF);
  const auto expect_pairs = [&](double ratio, const std::string& cluttered) {
    o.clutter_ratio = ratio;
    const auto roles = assign_split(names, o);
    for (int k = 0; k < 5; ++k) {
      const bool c = cluttered[size_t(k)] == 'x';
      const std::string tag = "ratio " + std::to_string(ratio) + " pair " + std::to_string(k);
      EXPECT_EQ(role_of(roles, "clutter" + std::to_string(k) + ".png"), c ? R::Train : R::Unused) << tag;
      EXPECT_EQ(role_of(roles, "clean" + std::to_string(k) + ".png"), c ? R::Unused : R::Train) << tag;
    }
    EXPECT_EQ(role_of(roles, "clutter9.png"), R::Unused);
    EXPECT_EQ(role_of(roles, "extra0.png"), R::Test);
  };
  // m = ⌊5·r⌋ cluttered pairs, pair k cluttered when ⌊(k+1)·m/5⌋ > ⌊k·m/5⌋.
  expect_pairs(0.0, ".....");
  expect_pairs(0.2, "....x");  // m = 1: only k = 4 crosses
  expect_pairs(0.4, "..x.x");  // m = 2: k = 2 (⌊6/5⌋ > ⌊4/5⌋) and k = 4
  expect_pairs(0.5, "..x.x");  // ⌊2.5⌋ = 2
  expect_pairs(0.8, ".xxxx");  // m = 4
  expect_pairs(1.0, "xxxxx");
  o.clutter_ratio = 1.5;
  EXPECT_CONTAINS(error_of(names, o), "clutter_ratio must be in [0, 1], got 1.5");
}

TEST(Splits, OnTheGoHoldsOutExtraImages) {
  EXPECT_EQ(assign_split({"extra_001.jpg", "clutter_001.jpg", "IMG_5.jpg", "dir/extra2.JPG", "extra/keep.jpg"},
                         rule(SplitRule::OnTheGo)),
            (std::vector<R>{R::Test, R::Train, R::Train, R::Test, R::Train}));  // folder names do not count
}

TEST(Splits, PhotoTourismTsv) {
  TempFile tsv("brandenburg.tsv",
               "filename\tid\tsplit\tdataset\n"
               "01.jpg\t0\ttrain\tbrandenburg\n"
               "02.jpg\t1\ttest\tbrandenburg\n"
               "03.jpg\t\ttrain\tbrandenburg\n"    // no id: skipped, as NeRF-W does
               "04.jpg\tnan\ttest\tbrandenburg\n"  // also skipped (and not in the model)
               "\n");
  SplitOptions o = rule(SplitRule::PhotoTourism);
  o.tsv = tsv.path;
  EXPECT_EQ(assign_split({"02.jpg", "01.jpg", "03.jpg", "05.jpg"}, o),
            (std::vector<R>{R::Test, R::Train, R::Unused, R::Unused}));
}

TEST(Splits, PhotoTourismErrors) {
  const std::vector<std::string> names = {"01.jpg", "02.jpg"};
  SplitOptions o = rule(SplitRule::PhotoTourism);
  EXPECT_CONTAINS(error_of(names, o), "needs a .tsv file");
  TempFile no_split("a.tsv", "filename\tid\tdataset\n01.jpg\t0\tx\n");
  o.tsv = no_split.path;
  EXPECT_CONTAINS(error_of(names, o), no_split.path.string() + ":1: the header has no 'split' column");
  TempFile bad_value("b.tsv", "filename\tid\tsplit\tdataset\n01.jpg\t0\tval\tx\n");
  o.tsv = bad_value.path;
  EXPECT_CONTAINS(error_of(names, o), bad_value.path.string() + ":2: split must be 'train' or 'test', got 'val'");
  TempFile unknown("c.tsv", "filename\tid\tsplit\tdataset\n01.jpg\t0\ttrain\tx\n09.jpg\t3\ttest\tx\n");
  o.tsv = unknown.path;
  EXPECT_CONTAINS(error_of(names, o), unknown.path.string() + ":3: '09.jpg' is not a registered image");
  TempFile conflict("d.tsv", "filename\tid\tsplit\tdataset\n01.jpg\t0\ttrain\tx\n01.jpg\t0\ttest\tx\n");
  o.tsv = conflict.path;
  EXPECT_CONTAINS(error_of(names, o), conflict.path.string() + ":3: '01.jpg' is listed as both train and test");
  TempFile short_row("e.tsv", "filename\tid\tsplit\tdataset\n01.jpg\t0\n");
  o.tsv = short_row.path;
  EXPECT_CONTAINS(error_of(names, o), short_row.path.string() + ":2: expected 4 tab-separated columns, got 2");
  TempFile only_test("f.tsv", "filename\tid\tsplit\tdataset\n01.jpg\t0\ttest\tx\n");
  o.tsv = only_test.path;
  EXPECT_CONTAINS(error_of(names, o), "leaves no training view");
}

TEST(Splits, ConflictingOptionsAreRejected) {
  const std::vector<std::string> names = {"a", "b", "c"};
  SplitOptions o;
  o.test_list = "t.txt";  // EveryNth does not read lists
  EXPECT_CONTAINS(error_of(names, o), "split rule 'every-nth' does not use train/test lists");
  o = rule(SplitRule::OnTheGo);
  o.every_nth = 4;
  EXPECT_CONTAINS(error_of(names, o), "split rule 'onthego' does not use every_nth");
  o = {};
  o.clutter_ratio = 0.5;
  EXPECT_CONTAINS(error_of(names, o), "does not use clutter_ratio");
  o = rule(SplitRule::NameLists);
  o.tsv = "x.tsv";
  EXPECT_CONTAINS(error_of(names, o), "does not use a .tsv file");
  o = {};
  o.every_nth = 1;
  EXPECT_CONTAINS(error_of(names, o), "every_nth must be at least 2, got 1");
  EXPECT_CONTAINS(error_of({"a", "a"}, rule(SplitRule::NameLists)), "needs a train list");
}

TEST(Splits, RuleNames) {
  EXPECT_EQ(split_rule_from_name("every-nth"), SplitRule::EveryNth);
  EXPECT_EQ(split_rule_from_name("robustnerf"), SplitRule::RobustNeRF);
  EXPECT_EQ(split_rule_from_name("phototourism"), SplitRule::PhotoTourism);
  EXPECT_THROW(split_rule_from_name("nerfstudio"), SplitError);
}

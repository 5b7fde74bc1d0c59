// The trainer as one rank of a data-parallel job (docs/METHOD.md §6, ranks): the batch's sums
// over ranks, the static statistics' totals, the shared random state, and the gathering of
// every view's state onto rank 0 for checkpoints and outputs.
#include <algorithm>
#include <stdexcept>
#include <type_traits>

#include "desplat/train/trainer.hpp"

namespace desplat {
namespace {

// Every rank's `g` becomes rank `root`'s: parameters, Adam moments and statistics.
void broadcast_trainable(Communicator& comm, TrainableGaussians& g, int root) {
  int64_t header[4] = {int64_t(g.params.color_mode), g.params.sh_degree, g.params.feature_dim, g.adam_step};
  comm.broadcast(std::as_writable_bytes(std::span<int64_t>(header)), root);
  int64_t empty = g.statistics_empty;
  comm.broadcast(std::as_writable_bytes(std::span<int64_t>(&empty, 1)), root);
  g.params.color_mode = ColorMode(header[0]);
  g.params.sh_degree = int(header[1]);
  g.params.feature_dim = int(header[2]);
  g.adam_step = header[3];
  g.statistics_empty = empty != 0;
  for (int k = 0; k < kParamGroups; ++k) {
    broadcast_vector(comm, g.param(ParamGroup(k)), root);
    broadcast_vector(comm, g.adam_m[k], root);
    broadcast_vector(comm, g.adam_v[k], root);
  }
  broadcast_vector(comm, g.absgrad_sum, root);
  broadcast_vector(comm, g.visible_count, root);
  broadcast_vector(comm, g.max_screen_radius, root);
  g.check_consistent();
}

// The values of views this rank does not own are zeroed, then summed over ranks: every rank
// ends with each owner's values.
template <typename T>
void share_owned(Communicator& comm, std::vector<T>& per_view, int rank, int ranks) {
  std::vector<std::conditional_t<std::is_floating_point_v<T>, T, int64_t>> values(per_view.size());
  for (size_t v = 0; v < per_view.size(); ++v) values[v] = rank_of_view(v, ranks) == rank ? per_view[v] : T(0);
  comm.sum(std::span(values));
  for (size_t v = 0; v < per_view.size(); ++v) per_view[v] = T(values[v]);
}

}  // namespace

void Trainer::sum_batch_over_ranks(StepStats& stats) {
  // A rank without a view in this batch adds zeros of the static set's shapes. One packed sum
  // for the gradients (and the visible flags), one for the step's figures: each collective is a
  // synchronization of every rank, so a step takes two.
  const bool none_here =
      std::none_of(batch_views_.begin(), batch_views_.end(), [&](const BatchView& bv) { return owns_view(bv.view); });
  // Of each colour row only the bands the update trains (update_static): the others' gradients
  // are never read.
  const size_t n_gaussians = gaussians_.size();
  const int64_t last = batch_views_.empty() ? step_ : batch_views_.back().index;
  const int sh_bands = config_.sh_degree_at(last) + 1;
  auto sent = [&](const ParamGroupInfo& info) {
    const size_t width = size_t(group_width(info, gaussians_.params));
    if (info.id != ParamGroup::Colors || gaussians_.params.color_mode != ColorMode::SphericalHarmonics) return width;
    return std::min(width, size_t(3 * sh_bands * sh_bands));
  };
  size_t total = config_.selective_adam ? n_gaussians : 0;
  for (const ParamGroupInfo& info : kParamGroupTable) {
    std::vector<float>& g = batch_grads_.*info.grads;
    const size_t n = (gaussians_.params.*info.values).size();
    if (none_here) g.assign(n, 0.0f);
    if (g.size() != n)
      throw std::logic_error(std::string("the batch's ") + info.name + " gradients have the wrong size");
    total += sent(info) * n_gaussians;
  }
  packed_.resize(total);
  size_t at = 0;
  for (const ParamGroupInfo& info : kParamGroupTable) {
    const std::vector<float>& g = batch_grads_.*info.grads;
    const size_t width = size_t(group_width(info, gaussians_.params)), used = sent(info);
    for (size_t i = 0; i < n_gaussians && used > 0; ++i, at += used)
      std::copy_n(g.begin() + ptrdiff_t(i * width), used, packed_.begin() + ptrdiff_t(at));
  }
  if (config_.selective_adam)
    for (size_t i = 0; i < n_gaussians; ++i) packed_[at + i] = none_here ? 0.0f : float(batch_visible_[i]);
  comm_->sum(std::span(packed_));
  at = 0;
  for (const ParamGroupInfo& info : kParamGroupTable) {
    std::vector<float>& g = batch_grads_.*info.grads;
    const size_t width = size_t(group_width(info, gaussians_.params)), used = sent(info);
    for (size_t i = 0; i < n_gaussians && used > 0; ++i, at += used)
      std::copy_n(packed_.begin() + ptrdiff_t(at), used, g.begin() + ptrdiff_t(i * width));
  }
  if (config_.selective_adam) {
    batch_visible_.resize(n_gaussians);
    for (size_t i = 0; i < n_gaussians; ++i) batch_visible_[i] = packed_[at + i] > 0;
  }
  // The views' figures, counts as doubles (exact below 2^53). Seeding comes after this sum:
  // `reseeded` counts this rank's views.
  double figures[6] = {stats.loss,
                       stats.psnr,
                       double(stats.static_pairs),
                       double(stats.static_visible),
                       double(stats.view_distractors),
                       double(stats.nonfinite_pruned)};
  comm_->sum(std::span<double>(figures));
  stats.loss = figures[0], stats.psnr = figures[1], stats.static_pairs = int64_t(figures[2]);
  stats.static_visible = size_t(figures[3]), stats.view_distractors = size_t(figures[4]);
  stats.nonfinite_pruned = int64_t(figures[5]);
}

void Trainer::reduce_static_statistics() {
  TrainableGaussians& g = gaussians_;
  comm_->sum(std::span(g.absgrad_sum));
  std::vector<int64_t> counts(g.visible_count.begin(), g.visible_count.end());
  comm_->sum(std::span(counts));
  std::copy(counts.begin(), counts.end(), g.visible_count.begin());
  // The maximum, rank by rank (the communicator sums; a maximum needs each rank's values).
  std::vector<float> theirs;
  std::vector<float> largest = g.max_screen_radius;
  for (int r = 0; r < ranks_; ++r) {
    theirs = g.max_screen_radius;
    comm_->broadcast(std::as_writable_bytes(std::span(theirs)), r);
    for (size_t i = 0; i < largest.size(); ++i) largest[i] = std::max(largest[i], theirs[i]);
  }
  g.max_screen_radius = std::move(largest);
  // Statistics are empty only where no rank recorded a view since the reset.
  int64_t recorded = !g.statistics_empty;
  comm_->sum(std::span<int64_t>(&recorded, 1));
  g.statistics_empty = recorded == 0;
}

void Trainer::follow_random_state(int root) {
  static_assert(std::is_trivially_copyable_v<std::mt19937_64>, "the engine's state is sent as its bytes");
  comm_->broadcast(std::as_writable_bytes(std::span<std::mt19937_64>(&rng_, 1)), root);
}

void Trainer::share_view_values() {
  if (view_seed_due.empty()) return;
  share_owned(*comm_, view_static_unexplained, rank_, ranks_);
  share_owned(*comm_, view_composite_unexplained, rank_, ranks_);
  share_owned(*comm_, view_seed_due, rank_, ranks_);
}

void Trainer::gather_to_root() {
  if (ranks_ == 1) return;
  share_view_values();
  for (size_t v = 0; v < distractors_.size(); ++v)
    broadcast_trainable(*comm_, distractors_[v], rank_of_view(v, ranks_));
  reduce_static_statistics();
}

void Trainer::keep_own_share() {
  if (ranks_ == 1) return;
  for (size_t v = 0; v < distractors_.size(); ++v)
    if (!owns_view(v)) {
      GaussianSet empty;
      empty.color_mode = ColorMode::RGB;
      distractors_[v] = TrainableGaussians(std::move(empty));
    }
  // The job's statistics are the sum over ranks: rank 0 holds them, the others count afresh.
  // statistics_empty stays the job's (the same on every rank; Trainer::train_view keeps it so).
  if (rank_ != 0) {
    std::fill(gaussians_.absgrad_sum.begin(), gaussians_.absgrad_sum.end(), 0.0f);
    std::fill(gaussians_.visible_count.begin(), gaussians_.visible_count.end(), 0);
  }
}

}  // namespace desplat

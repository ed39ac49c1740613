// Flatstream goodput on a loss-free bus, both directions fully loaded, next to the theoretical
// bound; and the CPU cost of one step.
//
// Bus model: an OutputSequence written in cycle t reaches the module in cycle t+2, an
// InputSequence written in cycle t reaches the CPU in cycle t+3, so one sequence takes a round
// trip of 5 bus cycles — the datasheet's X2X figure (write, bus, take + ack, bus, check).
//
// Bound (payload bytes per bus cycle) = sequences per cycle × payload per sequence:
//   sequences per cycle = min(1, Forward / round trip);
//   payload per sequence = MTU minus the control bytes the layout cannot avoid, for a stream of
//   equal messages of S bytes:
//     default         S / ceil(S / (MTU-1))               (one segment per sequence, tail wasted)
//     large segments  S / Σ ceil((seg+1) / MTU), seg ≤ 63 (each segment starts an MTU)
//     MultiSegmentMTU min(MTU-1, MTU·S/(S+1))             (a control byte per sequence and message)
//     large+multi     MTU·S / (S + ceil(S/63))            (only one control byte per 63 bytes)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <tuple>
#include <vector>

#include "flatstream/channel.hpp"

using namespace ds1928::flatstream;

namespace {

constexpr int kOutLatency = 2;
constexpr int kInLatency = 3;
constexpr int kRoundTrip = kOutLatency + kInLatency;

double payload_per_sequence(Layout layout, double mtu, std::size_t s) {
  if (s == 0) return 0;
  const double S = static_cast<double>(s);
  switch (layout) {
    case Layout::Default: {
      return S / std::ceil(S / (mtu - 1));
    }
    case Layout::LargeSegments: {
      double seqs = 0;
      for (std::size_t left = s; left > 0;) {
        const std::size_t seg = std::min<std::size_t>(left, 63);
        seqs += std::ceil((static_cast<double>(seg) + 1) / mtu);
        left -= seg;
      }
      return S / seqs;
    }
    case Layout::MultiSegmentMtu:
      return std::min(mtu - 1, mtu * S / (S + 1));
    case Layout::LargeMultiSegment:
      return mtu * S / (S + std::ceil(S / 63));
  }
  return 0;
}

double bound(Layout layout, uint8_t mtu, uint8_t forward, std::size_t s) {
  return std::min(1.0, double(forward) / kRoundTrip) * payload_per_sequence(layout, mtu, s);
}

struct Result {
  double in_goodput = 0;   // module → CPU, payload bytes per cycle
  double out_goodput = 0;  // CPU → module
  double master_ns = 0;    // median per step, clock overhead removed
  double module_ns = 0;
  double master_p99_ns = 0;
  double module_p99_ns = 0;
};

// Median and 99th percentile of per-call samples. The median is what one step costs; this
// machine is shared, and preemption only shows in the tail.
std::pair<double, double> median_p99(std::vector<int64_t>& v) {
  std::sort(v.begin(), v.end());
  return {double(v[v.size() / 2]), double(v[v.size() * 99 / 100])};
}

double clock_overhead_ns() {
  std::vector<int64_t> v(200000);
  for (auto& x : v) {
    const auto a = std::chrono::steady_clock::now();
    const auto b = std::chrono::steady_clock::now();
    x = (b - a).count();
  }
  return median_p99(v).first;
}

Result run(uint8_t mtu, Layout layout, uint8_t forward, std::size_t size, int cycles, bool timed) {
  MasterChannel master({mtu, mtu, layout, forward, 1000});
  ModuleChannel module({mtu, mtu, static_cast<uint8_t>(layout), forward, 0, 1000});
  std::vector<InputFrame> in_hist(kInLatency + 1);
  std::vector<OutputFrame> out_hist(kOutLatency + 1);
  std::vector<uint8_t> msg(size, 0xA5);
  const int warmup = 200;
  uint64_t in_bytes = 0, out_bytes = 0;
  Message m;
  std::vector<int64_t> t_master, t_module;
  if (timed) {
    t_master.reserve(static_cast<std::size_t>(cycles));
    t_module.reserve(static_cast<std::size_t>(cycles));
  }
  for (int t = 0; t < warmup + cycles; ++t) {
    while (master.take_outcome()) {
    }
    while (module.take_outcome()) {
    }
    while (!master.submit(msg, 0)) {
    }
    while (!module.submit(msg, 0)) {
    }
    const InputFrame in_view = in_hist[static_cast<std::size_t>(t) % in_hist.size()];
    const auto a = std::chrono::steady_clock::now();
    const OutputFrame out = master.step(in_view, static_cast<uint64_t>(t) * 100);
    const auto b = std::chrono::steady_clock::now();
    out_hist[static_cast<std::size_t>(t + kOutLatency) % out_hist.size()] = out;
    const OutputFrame out_view = out_hist[static_cast<std::size_t>(t) % out_hist.size()];
    const auto c = std::chrono::steady_clock::now();
    const InputFrame in = module.step(out_view, static_cast<uint64_t>(t) * 100);
    const auto d = std::chrono::steady_clock::now();
    in_hist[static_cast<std::size_t>(t + kInLatency) % in_hist.size()] = in;
    if (timed && t >= warmup) {
      t_master.push_back((b - a).count());
      t_module.push_back((d - c).count());
    }
    while (master.take_received(m)) {
      if (t >= warmup) in_bytes += m.size;
    }
    while (module.take_received(m)) {
      if (t >= warmup) out_bytes += m.size;
    }
  }
  Result r;
  r.in_goodput = double(in_bytes) / cycles;
  r.out_goodput = double(out_bytes) / cycles;
  if (timed) {
    const double clock = clock_overhead_ns();
    std::tie(r.master_ns, r.master_p99_ns) = median_p99(t_master);
    std::tie(r.module_ns, r.module_p99_ns) = median_p99(t_module);
    r.master_ns -= clock;
    r.module_ns -= clock;
    r.master_p99_ns -= clock;
    r.module_p99_ns -= clock;
  }
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const int cycles = quick ? 5000 : 40000;
  const Layout layouts[] = {Layout::Default, Layout::MultiSegmentMtu, Layout::LargeSegments,
                            Layout::LargeMultiSegment};
  const uint8_t mtus[] = {2, 3, 5, 7, 10, 15, 27};
  const uint8_t forwards[] = {1, 3, 5, 7};

  std::printf("Flatstream goodput, loss-free bus, round trip %d cycles, both directions loaded\n",
              kRoundTrip);
  std::printf("payload bytes per bus cycle: measured / bound (%% of bound); S = message size\n\n");
  std::printf("%4s %-13s %3s | %-24s | %-24s | %-24s\n", "MTU", "layout", "Fwd", "input S=8",
              "input S=300", "output S=300");
  bool goal_met = true;
  for (uint8_t mtu : mtus) {
    for (Layout layout : layouts) {
      for (uint8_t fwd : forwards) {
        const Result small = run(mtu, layout, fwd, 8, cycles, false);
        const Result large = run(mtu, layout, fwd, 300, cycles, false);
        const double b8 = bound(layout, mtu, fwd, 8), b300 = bound(layout, mtu, fwd, 300);
        std::printf(
            "%4d %-13s %3d | %6.2f / %6.2f (%5.1f%%) | %6.2f / %6.2f (%5.1f%%) | %6.2f / %6.2f "
            "(%5.1f%%)\n",
            mtu, to_string(layout), fwd, small.in_goodput, b8, 100 * small.in_goodput / b8,
            large.in_goodput, b300, 100 * large.in_goodput / b300, large.out_goodput, b300,
            100 * large.out_goodput / b300);
        if (fwd == 7 && layout == Layout::LargeMultiSegment && mtu >= 3) {
          goal_met = goal_met && large.in_goodput >= 0.9 * b300 && small.in_goodput >= 0.9 * b8 &&
                     large.out_goodput >= 0.9 * b300;
        }
      }
    }
  }
  std::printf("\nGoal (Forward 7, large+multi, >= 90%% of bound): %s\n\n",
              goal_met ? "met" : "MISSED");

  std::printf(
      "CPU cost of one step (both directions busy, S=300), ns per call, median / p99,\n"
      "clock read overhead (%.0f ns) removed:\n",
      clock_overhead_ns());
  std::printf("%4s %-13s %3s %16s %16s\n", "MTU", "layout", "Fwd", "master", "module");
  for (uint8_t mtu : {uint8_t{5}, uint8_t{15}, uint8_t{27}}) {
    for (Layout layout : {Layout::Default, Layout::LargeMultiSegment}) {
      const Result r = run(mtu, layout, 7, 300, quick ? 20000 : 400000, true);
      std::printf("%4d %-13s %3d %7.0f / %6.0f %7.0f / %6.0f\n", mtu, to_string(layout), 7,
                  r.master_ns, r.master_p99_ns, r.module_ns, r.module_p99_ns);
    }
  }
  return goal_met ? 0 : 1;
}

// cv_tracker.cpp: a constant-velocity pose tracker speaking the roft_sim tracker process protocol
// (version 1, docs/process.md) on stdin/stdout. Standard library only; C++17.
//
// It keeps the newest pose detection by capture frame, takes the velocity from the last two (by
// capture time capture_k / fps) and extrapolates to the current frame. Detections not newer than
// the one held are dropped. cv_tracker.py is the same tracker in Python, operation for operation,
// so both give the same bits. Logs go to stderr: stdout carries the protocol only.
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "msgpack_lite.hpp"

using msgpack_lite::Value;
using msgpack_lite::Writer;

namespace {

constexpr int64_t kProtocolVersion = 1;
using Vec = std::array<double, 3>;
using Quat = std::array<double, 4>;  // (w, x, y, z)

// ------------------------------------------------------------------------------ framing
// A frame: uint32 little-endian payload length, then the MessagePack payload.
bool read_frame(std::vector<uint8_t>& payload) {
  uint8_t h[4];
  if (std::fread(h, 1, 4, stdin) != 4) return false;  // end of stdin
  const uint32_t n = h[0] | (h[1] << 8) | (h[2] << 16) | (static_cast<uint32_t>(h[3]) << 24);
  payload.resize(n);
  if (n > 0 && std::fread(payload.data(), 1, n, stdin) != n)
    throw std::runtime_error("stdin ended inside a frame");
  return true;
}

void write_frame(const std::string& payload) {
  const uint32_t n = static_cast<uint32_t>(payload.size());
  const uint8_t h[4] = {uint8_t(n), uint8_t(n >> 8), uint8_t(n >> 16), uint8_t(n >> 24)};
  std::fwrite(h, 1, 4, stdout);
  std::fwrite(payload.data(), 1, payload.size(), stdout);
  std::fflush(stdout);
}

// -------------------------------------------------------------------------------- arrays
// An array travels as {"dtype", "shape", "data"}; data is C-order little-endian.
template <size_t N>
std::array<double, N> read_f64(const Value& array, const char* field) {
  if (array.at("dtype").as_str() != "float64" || array.at("data").bytes.size() != 8 * N)
    throw std::runtime_error(std::string(field) + ": expected " + std::to_string(N) + " float64");
  std::array<double, N> out{};
  const auto* p = reinterpret_cast<const uint8_t*>(array.at("data").bytes.data());
  for (size_t k = 0; k < N; ++k) {
    uint64_t u = 0;
    for (int b = 7; b >= 0; --b) u = (u << 8) | p[8 * k + b];
    std::memcpy(&out[k], &u, 8);
  }
  return out;
}

template <size_t N>
void write_f64(Writer& w, const std::array<double, N>& values) {
  std::string data(8 * N, '\0');
  for (size_t k = 0; k < N; ++k) {
    uint64_t u;
    std::memcpy(&u, &values[k], 8);
    for (int b = 0; b < 8; ++b) data[8 * k + b] = static_cast<char>((u >> (8 * b)) & 0xff);
  }
  w.map(3);
  w.key("dtype"); w.str("float64");
  w.key("shape"); w.array(1); w.integer(N);
  w.key("data"); w.bin(data.data(), data.size());
}

// ---------------------------------------------------------------------------- quaternions
Quat multiply(const Quat& a, const Quat& b) {  // Hamilton product a * b
  return {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
          a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
          a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
          a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
}

Vec rotvec_from_quat(Quat q) {  // rotation vector [rad], the short way round
  if (q[0] < 0.0) q = {-q[0], -q[1], -q[2], -q[3]};
  const double n = std::sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (n == 0.0) return {0.0, 0.0, 0.0};
  const double s = 2.0 * std::atan2(n, q[0]) / n;
  return {s * q[1], s * q[2], s * q[3]};
}

Quat quat_from_rotvec(const Vec& r) {
  const double angle = std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
  if (angle == 0.0) return {1.0, 0.0, 0.0, 0.0};
  const double s = std::sin(0.5 * angle) / angle;
  return {std::cos(0.5 * angle), s * r[0], s * r[1], s * r[2]};
}

Quat normalized(const Quat& q) {
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  return {q[0] / n, q[1] / n, q[2] / n, q[3] / n};
}

// -------------------------------------------------------------------------------- tracker
struct Tracker {
  int64_t fps = 30;
  bool has_pose = false;
  int64_t k_last = 0;
  Vec t_last{0, 0, 0}, v{0, 0, 0}, w{0, 0, 0};
  Quat q_last{1, 0, 0, 0};

  void reset(const Value& initial) {
    has_pose = !initial.is_nil();
    k_last = 0;
    t_last = v = w = {0, 0, 0};
    q_last = {1, 0, 0, 0};
    if (!has_pose) return;
    k_last = initial.at("k").as_int();
    t_last = read_f64<3>(initial.at("t_m"), "initial.t_m");
    q_last = read_f64<4>(initial.at("q_wxyz"), "initial.q_wxyz");
    v = read_f64<3>(initial.at("v_obj_mps"), "initial.v_obj_mps");
    w = read_f64<3>(initial.at("w_radps"), "initial.w_radps");
  }

  void take(int64_t capture_k, const Vec& t, const Quat& q) {
    if (has_pose) {
      const double dt = static_cast<double>(capture_k - k_last) / static_cast<double>(fps);
      v = {(t[0] - t_last[0]) / dt, (t[1] - t_last[1]) / dt, (t[2] - t_last[2]) / dt};
      const Vec r = rotvec_from_quat(multiply(q, {q_last[0], -q_last[1], -q_last[2], -q_last[3]}));
      w = {r[0] / dt, r[1] / dt, r[2] / dt};
    }
    has_pose = true;
    k_last = capture_k;
    t_last = t;
    q_last = q;
  }

  std::string step(const Value& observation) {
    const int64_t k = observation.at("k").as_int();
    std::vector<int64_t> accepted, dropped;
    for (const Value& pose : observation.at("poses").items) {
      const int64_t capture_k = pose.at("capture_k").as_int();
      const int64_t id = pose.at("detection_id").as_int();
      if (has_pose && capture_k <= k_last) { dropped.push_back(id); continue; }
      take(capture_k, read_f64<3>(pose.at("t_m"), "pose.t_m"),
           read_f64<4>(pose.at("q_wxyz"), "pose.q_wxyz"));
      accepted.push_back(id);
    }
    Vec t{0, 0, 0};
    Quat q{1, 0, 0, 0};
    if (has_pose) {
      const double tau = static_cast<double>(k - k_last) / static_cast<double>(fps);
      t = {t_last[0] + v[0] * tau, t_last[1] + v[1] * tau, t_last[2] + v[2] * tau};
      q = normalized(multiply(quat_from_rotvec({w[0] * tau, w[1] * tau, w[2] * tau}), q_last));
    }
    Writer out;
    out.map(9);
    out.key("type"); out.str("estimate");
    out.key("k"); out.integer(k);
    out.key("valid"); out.boolean(has_pose);
    out.key("t_m"); write_f64<3>(out, t);
    out.key("q_wxyz"); write_f64<4>(out, q);
    out.key("v_obj_mps"); write_f64<3>(out, has_pose ? v : Vec{0, 0, 0});
    out.key("w_radps"); write_f64<3>(out, has_pose ? w : Vec{0, 0, 0});
    out.key("accepted_pose_ids"); out.array(accepted.size());
    for (int64_t id : accepted) out.integer(id);
    out.key("dropped_pose_ids"); out.array(dropped.size());
    for (int64_t id : dropped) out.integer(id);
    return out.out;
  }
};

// "shm": true accepts large arrays (images, flow, masks) in the shared file that hello offers:
// this tracker reads none of them, so they cost it nothing. A tracker that reads them opens
// hello["shm"]["path"] before replying and reads each at its "shm_offset" (docs/process.md);
// replying false gets them inline as "data" instead.
std::string ready() {
  Writer w;
  w.map(4);
  w.key("type"); w.str("ready");
  w.key("protocol"); w.integer(kProtocolVersion);
  w.key("name"); w.str("cv_tracker_cpp");
  w.key("shm"); w.boolean(true);
  return w.out;
}

std::string error(const std::string& text) {
  Writer w;
  w.map(2);
  w.key("type"); w.str("error");
  w.key("message"); w.str(text);
  return w.out;
}

}  // namespace

int main() {
  Tracker tracker;
  std::vector<uint8_t> payload;
  try {
    while (read_frame(payload)) {
      const Value message = msgpack_lite::Reader(payload.data(), payload.size()).read();
      const std::string_view type = message.at("type").as_str();
      if (type == "hello") {
        if (message.at("protocol").as_int() != kProtocolVersion)
          throw std::runtime_error("unsupported protocol version");
        tracker.fps = message.at("fps").as_int();
        write_frame(ready());
      } else if (type == "reset") {
        tracker.reset(message.at("initial"));
        write_frame(ready());
      } else if (type == "observation") {
        write_frame(tracker.step(message));
      } else if (type == "bye") {
        return 0;
      } else {
        throw std::runtime_error("unknown message type '" + std::string(type) + "'");
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cv_tracker: %s\n", e.what());
    write_frame(error(e.what()));
    return 1;
  }
  return 0;
}

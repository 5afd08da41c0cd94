// msgpack_lite.hpp: the MessagePack subset the tracker process protocol uses (docs/process.md).
//
// Reader: nil, bool, integers, float32/64, str, bin, array and map into a small value tree whose
// strings and buffers point into the frame (no copy). Writer: the same types, appended to a
// std::string. Standard library only; C++17. Not a general MessagePack library: no ext types,
// no timestamps.
#pragma once

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace msgpack_lite {

struct Value {
  enum class Kind { Nil, Bool, Int, Float, Str, Bin, Array, Map };
  Kind kind = Kind::Nil;
  bool b = false;
  int64_t i = 0;
  double f = 0.0;
  std::string_view bytes;  // Str and Bin: a view into the frame
  std::vector<Value> items;                  // Array
  std::vector<std::pair<std::string_view, Value>> fields;  // Map (string keys only)

  bool is_nil() const { return kind == Kind::Nil; }
  // The field named `key` of a map, or nullptr.
  const Value* find(std::string_view key) const {
    for (const auto& kv : fields)
      if (kv.first == key) return &kv.second;
    return nullptr;
  }
  // The field named `key`; throws when the map lacks it.
  const Value& at(std::string_view key) const {
    const Value* v = find(key);
    if (v == nullptr) throw std::runtime_error("missing field '" + std::string(key) + "'");
    return *v;
  }
  int64_t as_int() const {
    if (kind != Kind::Int) throw std::runtime_error("expected an integer");
    return i;
  }
  double as_double() const {
    if (kind == Kind::Float) return f;
    if (kind == Kind::Int) return static_cast<double>(i);
    throw std::runtime_error("expected a number");
  }
  std::string_view as_str() const {
    if (kind != Kind::Str) throw std::runtime_error("expected a string");
    return bytes;
  }
};

class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : p_(data), end_(data + size) {}

  Value read() {
    const uint8_t t = byte();
    Value v;
    if (t <= 0x7f) return integer(t);
    if (t >= 0xe0) return integer(static_cast<int8_t>(t));
    if ((t & 0xf0) == 0x80) return map(t & 0x0f);
    if ((t & 0xf0) == 0x90) return array(t & 0x0f);
    if ((t & 0xe0) == 0xa0) return str(Value::Kind::Str, t & 0x1f);
    switch (t) {
      case 0xc0: return v;
      case 0xc2: case 0xc3: v.kind = Value::Kind::Bool; v.b = (t == 0xc3); return v;
      case 0xc4: return str(Value::Kind::Bin, uint(1));
      case 0xc5: return str(Value::Kind::Bin, uint(2));
      case 0xc6: return str(Value::Kind::Bin, uint(4));
      case 0xca: { uint32_t u = static_cast<uint32_t>(uint(4)); float x; std::memcpy(&x, &u, 4); return real(x); }
      case 0xcb: { uint64_t u = uint(8); double x; std::memcpy(&x, &u, 8); return real(x); }
      case 0xcc: return integer(static_cast<int64_t>(uint(1)));
      case 0xcd: return integer(static_cast<int64_t>(uint(2)));
      case 0xce: return integer(static_cast<int64_t>(uint(4)));
      case 0xcf: return integer(static_cast<int64_t>(uint(8)));
      case 0xd0: return integer(static_cast<int8_t>(uint(1)));
      case 0xd1: return integer(static_cast<int16_t>(uint(2)));
      case 0xd2: return integer(static_cast<int32_t>(uint(4)));
      case 0xd3: return integer(static_cast<int64_t>(uint(8)));
      case 0xd9: return str(Value::Kind::Str, uint(1));
      case 0xda: return str(Value::Kind::Str, uint(2));
      case 0xdb: return str(Value::Kind::Str, uint(4));
      case 0xdc: return array(uint(2));
      case 0xdd: return array(uint(4));
      case 0xde: return map(uint(2));
      case 0xdf: return map(uint(4));
      default: throw std::runtime_error("unsupported MessagePack type byte " + std::to_string(t));
    }
  }

 private:
  const uint8_t* p_;
  const uint8_t* end_;

  void need(size_t n) const {
    if (static_cast<size_t>(end_ - p_) < n) throw std::runtime_error("truncated MessagePack");
  }
  uint8_t byte() { need(1); return *p_++; }
  uint64_t uint(int n) {  // big-endian, as MessagePack stores lengths and numbers
    need(n);
    uint64_t u = 0;
    for (int k = 0; k < n; ++k) u = (u << 8) | *p_++;
    return u;
  }
  static Value integer(int64_t x) { Value v; v.kind = Value::Kind::Int; v.i = x; return v; }
  static Value real(double x) { Value v; v.kind = Value::Kind::Float; v.f = x; return v; }
  Value str(Value::Kind kind, uint64_t n) {
    need(n);
    Value v;
    v.kind = kind;
    v.bytes = std::string_view(reinterpret_cast<const char*>(p_), n);
    p_ += n;
    return v;
  }
  Value array(uint64_t n) {
    Value v;
    v.kind = Value::Kind::Array;
    for (uint64_t k = 0; k < n; ++k) v.items.push_back(read());
    return v;
  }
  Value map(uint64_t n) {
    Value v;
    v.kind = Value::Kind::Map;
    for (uint64_t k = 0; k < n; ++k) {
      Value key = read();
      v.fields.emplace_back(key.as_str(), read());
    }
    return v;
  }
};

// Appends MessagePack to a byte string.
class Writer {
 public:
  std::string out;

  void nil() { out.push_back(static_cast<char>(0xc0)); }
  void boolean(bool b) { out.push_back(static_cast<char>(b ? 0xc3 : 0xc2)); }
  void integer(int64_t x) {
    if (x >= 0 && x <= 0x7f) { out.push_back(static_cast<char>(x)); return; }
    if (x < 0 && x >= -32) { out.push_back(static_cast<char>(static_cast<int8_t>(x))); return; }
    out.push_back(static_cast<char>(0xd3));
    be(static_cast<uint64_t>(x), 8);
  }
  void real(double x) {
    uint64_t u;
    std::memcpy(&u, &x, 8);
    out.push_back(static_cast<char>(0xcb));
    be(u, 8);
  }
  void str(std::string_view s) {
    out.push_back(static_cast<char>(0xdb));
    be(s.size(), 4);
    out.append(s);
  }
  void bin(const void* data, size_t n) {
    out.push_back(static_cast<char>(0xc6));
    be(n, 4);
    out.append(static_cast<const char*>(data), n);
  }
  void array(uint32_t n) { out.push_back(static_cast<char>(0xdd)); be(n, 4); }
  void map(uint32_t n) { out.push_back(static_cast<char>(0xdf)); be(n, 4); }
  void key(std::string_view k) { str(k); }

 private:
  void be(uint64_t u, int n) {
    for (int k = n - 1; k >= 0; --k) out.push_back(static_cast<char>((u >> (8 * k)) & 0xff));
  }
};

}  // namespace msgpack_lite

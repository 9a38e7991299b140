// Fuzz target: untrusted bytes off the wire -> Cyclone DDS's own CDR
// validation and decoding (dds_stream_normalize + dds_stream_read_sample, the
// path a received sample takes) -> the daemon's input validation. Nothing may
// crash, hang, leak or read out of bounds; accepted trajectories must yield
// segments that obey the limits.
//
// Built two ways:
//  - with clang -fsanitize=fuzzer (PVCGEL_FUZZ=ON): the libFuzzer binary `fuzz_dds_input`;
//  - always: `fuzz_dds_input_replay`, which runs every file of the corpus
//    (tests/fuzz/corpus) through the same function as a ctest, and writes
//    the seed corpus with --seed DIR.
#include <dds/dds.h>
#include <dds/ddsi/ddsi_cdrstream.h>
#include <dds/ddsi/ddsi_serdata_default.h>
#include <dds/ddsi/q_protocol.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include "daemon/dds/dds_messages.hpp"

using namespace pvcgel::daemon;

namespace {

/// The minimal sertype Cyclone's stream functions need for one generated type.
struct Sertype {
  explicit Sertype(const dds_topic_descriptor_t& d) {
    st.encoding_format = CDR_ENC_FORMAT_PLAIN;
    st.write_encoding_version = CDR_ENC_VERSION_1;
    st.type.size = d.m_size;
    st.type.align = d.m_align;
    st.type.flagset = d.m_flagset;
    for (uint32_t i = 0; i < d.m_nkeys; ++i) keys.push_back({d.m_keys[i].m_offset, d.m_keys[i].m_idx});
    st.type.keys.nkeys = d.m_nkeys;
    st.type.keys.keys = keys.data();
    st.type.ops.nops = dds_stream_countops(d.m_ops, d.m_nkeys, d.m_keys);
    st.type.ops.ops = const_cast<uint32_t*>(d.m_ops);
  }
  std::vector<ddsi_sertype_default_desc_key_t> keys;
  ddsi_sertype_default st{};
};

const Sertype& trajectory_type() {
  static const Sertype t(pvcgel_v1_Trajectory_desc);
  return t;
}
const Sertype& command_type() {
  static const Sertype t(pvcgel_v1_Command_desc);
  return t;
}

/// Decodes `size` bytes as a sample of `type` into `sample` (zeroed, of the
/// type's size); false when Cyclone's validation refuses the bytes.
bool decode(const Sertype& type, const uint8_t* data, size_t size, void* sample) {
  if (size > 1u << 20) return false;
  std::vector<unsigned char> buf(data, data + size);
  uint32_t actual = 0;
  if (!dds_stream_normalize(buf.data(), static_cast<uint32_t>(buf.size()), false, CDR_ENC_VERSION_1, &type.st, false, &actual))
    return false;
  dds_istream_t is;
  dds_istream_init(&is, actual, buf.data(), CDR_ENC_VERSION_1);
  dds_stream_read_sample(&is, sample, &type.st);
  dds_istream_fini(&is);
  return true;
}

void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "fuzz invariant violated: %s\n", what);
    std::abort();
  }
}

void fuzz_trajectory(const uint8_t* data, size_t size) {
  pvcgel_v1_Trajectory t{};
  if (!decode(trajectory_type(), data, size, &t)) return;
  const TrajectoryMessage m = pvcgel::dds::to_trajectory_message(t);  // exactly what the daemon validates
  const SetpointLimits limits;
  LoopView loop;
  loop.now_s = 5.0;
  loop.target = static_cast<LoopTarget>(t.publish_time_ns & 1);
  std::vector<SetpointSegment> out;
  const Verdict v = validate_trajectory(m, limits, loop, out);
  check(v.ok() == !out.empty(), "segments exist exactly when accepted");
  check(v.ok() || !v.detail.empty(), "a refusal names its reason");
  for (const auto& s : out) {
    check(s.count >= 1 && s.count <= SetpointSegment::kMaxValues, "piece size");
    const double lo = s.target == LoopTarget::voltage ? limits.min_V : limits.min_um;
    const double hi = s.target == LoopTarget::voltage ? limits.max_V : limits.max_um;
    for (double tt : {s.start_s, s.start_s + 0.37, s.start_s + 12.5}) {
      const double r = segment_value(s, tt);
      check(std::isfinite(r), "finite setpoint");
      check(r >= lo - 1e-6 && r <= hi + 1e-6, "setpoint inside the limits");
    }
  }
  dds_stream_free_sample(&t, pvcgel_v1_Trajectory_desc.m_ops);
}

void fuzz_command(const uint8_t* data, size_t size) {
  pvcgel_v1_Command c{};
  if (!decode(command_type(), data, size, &c)) return;
  const Verdict v = validate_command(c.kind, c.argument, c.client_id, c.command_seq);
  check(v.ok() || !v.detail.empty(), "a refusal names its reason");
  if (v.ok()) check(c.kind >= 1 && c.kind <= 7, "only known commands pass");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  if (data[0] & 1) fuzz_command(data + 1, size - 1);
  else fuzz_trajectory(data + 1, size - 1);
  return 0;
}

#ifndef PVCGEL_LIBFUZZER
namespace {

std::vector<uint8_t> encode(const Sertype& type, const void* sample, uint8_t selector) {
  dds_ostream_t os;
  dds_ostream_init(&os, 0, CDR_ENC_VERSION_1);
  check(dds_stream_write_sample(&os, sample, &type.st), "encode seed");
  std::vector<uint8_t> out(1 + os.m_index);
  out[0] = selector;
  std::copy_n(os.m_buffer, os.m_index, out.begin() + 1);
  dds_ostream_fini(&os);
  return out;
}

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  int n = 0;
  auto save = [&](const std::vector<uint8_t>& bytes) {
    std::ofstream(dir / ("seed-" + std::to_string(n++)), std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  };
  struct Seed {
    uint8_t kind, timing;
    std::vector<double> values;
    double duration_s, start_s;
  };
  const Seed seeds[] = {{1, 0, {50}, 0, -1},
                        {2, 1, {10, 60}, 3, -1},
                        {3, 0, {100, 25, 1, 0}, 0, 6},
                        {4, 0, {96, 5, 0.1, 0, 7, 0.5, 0, 12, 1, 0}, 0, -1},
                        {0, 1, {10, 10.5, 11, 11.5, 12}, 0, -1},
                        {3, 0, {NAN, 1, 1, 0}, 0, -1}};
  for (const auto& s : seeds) {
    std::vector<double> v = s.values;
    pvcgel_v1_Trajectory t{};
    std::snprintf(t.rig_id, sizeof t.rig_id, "rig1");
    std::snprintf(t.client_id, sizeof t.client_id, "seed");
    t.chunk_seq = 1;
    t.kind = s.kind;
    t.timing = s.timing;
    t.start_time_s = s.start_s;
    t.period_s = 1e-3;
    t.duration_s = s.duration_s;
    t.blend_s = 1.0;
    t.values._buffer = v.data();
    t.values._length = t.values._maximum = static_cast<uint32_t>(v.size());
    const auto bytes = encode(trajectory_type(), &t, 0);
    pvcgel_v1_Trajectory back{};
    check(decode(trajectory_type(), bytes.data() + 1, bytes.size() - 1, &back), "a seed decodes");
    check(back.kind == t.kind && back.values._length == t.values._length && std::strcmp(back.client_id, "seed") == 0,
          "a seed decodes to what was encoded");
    dds_stream_free_sample(&back, pvcgel_v1_Trajectory_desc.m_ops);
    save(bytes);
  }
  for (uint8_t kind = 0; kind <= 8; ++kind) {
    pvcgel_v1_Command c{};
    std::snprintf(c.rig_id, sizeof c.rig_id, "rig1");
    std::snprintf(c.client_id, sizeof c.client_id, "seed");
    c.command_seq = kind;
    c.kind = kind;
    c.argument = kind == 5 ? 2 : kind == 6 ? 1 : 0;
    save(encode(command_type(), &c, 1));
  }
  std::printf("wrote %d seeds to %s\n", n, dir.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "--seed") {
    write_seeds(argv[2]);
    return 0;
  }
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR | --seed DIR\n", argv[0]);
    return 2;
  }
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(argv[1])) {
    if (!e.is_regular_file()) continue;
    std::ifstream f(e.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    LLVMFuzzerTestOneInput(bytes.data(), bytes.size());
    ++files;
  }
  std::printf("replayed %d corpus files from %s without a failure\n", files, argv[1]);
  return files > 0 ? 0 : 1;
}
#endif

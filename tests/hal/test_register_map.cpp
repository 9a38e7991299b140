// Register formats and linear maps: every width, sign and word order, at and beyond the limits.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>

#include "hal/register_map.hpp"

using namespace pvcgel::hal;

namespace {
const RegisterFormat kU16{16, false, WordOrder::high_first};
const RegisterFormat kS16{16, true, WordOrder::high_first};
const RegisterFormat kU32Hi{32, false, WordOrder::high_first};
const RegisterFormat kS32Hi{32, true, WordOrder::high_first};
const RegisterFormat kU32Lo{32, false, WordOrder::low_first};
const RegisterFormat kS32Lo{32, true, WordOrder::low_first};
}  // namespace

TEST(RegisterMap, RangesOfEveryFormat) {
  EXPECT_EQ(kU16.min_counts(), 0);
  EXPECT_EQ(kU16.max_counts(), 65535);
  EXPECT_EQ(kS16.min_counts(), -32768);
  EXPECT_EQ(kS16.max_counts(), 32767);
  EXPECT_EQ(kU32Hi.min_counts(), 0);
  EXPECT_EQ(kU32Hi.max_counts(), 4294967295LL);
  EXPECT_EQ(kS32Lo.min_counts(), -2147483648LL);
  EXPECT_EQ(kS32Lo.max_counts(), 2147483647LL);
  EXPECT_EQ(kU16.register_count(), 1);
  EXPECT_EQ(kS32Hi.register_count(), 2);
}

TEST(RegisterMap, Decodes16BitSignedAndUnsigned) {
  const std::uint16_t r[] = {0xFFFE};
  EXPECT_EQ(decode_counts(r, kU16), 65534);
  EXPECT_EQ(decode_counts(r, kS16), -2);
  const std::uint16_t m[] = {0x8000};
  EXPECT_EQ(decode_counts(m, kS16), -32768);
  EXPECT_EQ(decode_counts(m, kU16), 32768);
}

TEST(RegisterMap, Decodes32BitInBothWordOrders) {
  const std::uint16_t r[] = {0x1234, 0x5678};
  EXPECT_EQ(decode_counts(r, kU32Hi), 0x12345678);
  EXPECT_EQ(decode_counts(r, kU32Lo), 0x56781234);
  const std::uint16_t neg[] = {0xFFFF, 0xFFFE};  // -2 high word first
  EXPECT_EQ(decode_counts(neg, kS32Hi), -2);
  EXPECT_EQ(decode_counts(neg, kU32Hi), 4294967294LL);
  EXPECT_EQ(decode_counts(neg, kS32Lo), static_cast<std::int32_t>(0xFFFEFFFFu));
}

TEST(RegisterMap, EncodeDecodeRoundTripsAcrossEveryFormat) {
  for (const auto& f : {kU16, kS16, kU32Hi, kS32Hi, kU32Lo, kS32Lo}) {
    const std::int64_t lo = f.min_counts(), hi = f.max_counts();
    for (const std::int64_t c : {lo, lo + 1, std::int64_t{0}, std::int64_t{1}, std::int64_t{12345}, hi - 1, hi}) {
      if (c < lo || c > hi) continue;
      std::uint16_t regs[2] = {0xAAAA, 0xAAAA};
      ASSERT_TRUE(encode_counts(c, f, regs)) << c;
      EXPECT_EQ(decode_counts(regs, f), c) << "width " << int(f.width_bits) << " signed " << f.is_signed;
      if (f.width_bits == 16) {
        EXPECT_EQ(regs[1], 0xAAAA) << "a 16-bit value must not touch the next register";
      }
    }
    // A stride through the whole 16-bit range, and a multiplicative walk through the 32-bit one.
    for (std::int64_t c = lo; c <= hi && f.width_bits == 16; c += 97) {
      std::uint16_t regs[1];
      ASSERT_TRUE(encode_counts(c, f, regs));
      ASSERT_EQ(decode_counts(regs, f), c);
    }
    for (double x = 1.0; f.width_bits == 32 && x < static_cast<double>(hi); x *= 1.37) {
      for (const auto c : {static_cast<std::int64_t>(x), f.is_signed ? -static_cast<std::int64_t>(x) : std::int64_t{0}}) {
        std::uint16_t regs[2];
        ASSERT_TRUE(encode_counts(c, f, regs));
        ASSERT_EQ(decode_counts(regs, f), c);
      }
    }
  }
}

TEST(RegisterMap, EncodePutsWordsInConfiguredOrder) {
  std::uint16_t regs[2];
  ASSERT_TRUE(encode_counts(0x12345678, kU32Hi, regs));
  EXPECT_EQ(regs[0], 0x1234);
  EXPECT_EQ(regs[1], 0x5678);
  ASSERT_TRUE(encode_counts(0x12345678, kU32Lo, regs));
  EXPECT_EQ(regs[0], 0x5678);
  EXPECT_EQ(regs[1], 0x1234);
  ASSERT_TRUE(encode_counts(-1, kS16, regs));
  EXPECT_EQ(regs[0], 0xFFFF);
}

TEST(RegisterMap, EncodeRejectsOutOfRangeAndLeavesRegistersAlone) {
  std::uint16_t regs[2] = {7, 7};
  EXPECT_FALSE(encode_counts(-1, kU16, regs));
  EXPECT_FALSE(encode_counts(65536, kU16, regs));
  EXPECT_FALSE(encode_counts(32768, kS16, regs));
  EXPECT_FALSE(encode_counts(-32769, kS16, regs));
  EXPECT_FALSE(encode_counts(4294967296LL, kU32Hi, regs));
  EXPECT_FALSE(encode_counts(2147483648LL, kS32Lo, regs));
  EXPECT_EQ(regs[0], 7);
  EXPECT_EQ(regs[1], 7);
}

TEST(RegisterMap, WordOrderNames) {
  EXPECT_EQ(pvcgel::parse_enum<WordOrder>("high_first"), WordOrder::high_first);
  EXPECT_EQ(pvcgel::parse_enum<WordOrder>("low_first"), WordOrder::low_first);
  EXPECT_FALSE(pvcgel::parse_enum<WordOrder>("big").has_value());
}

TEST(RegisterMap, SensorChannelDecodesMicrometresFromABlock) {
  // Sensor at register 4 of a block starting at 2: 0.001 um/count, offset -10 um.
  const InputChannel sensor{4, kS32Hi, {0.001, -10.0}};
  const std::uint16_t block[] = {0, 0, 0x0001, 0xE240};  // 123456 counts
  EXPECT_NEAR(sensor.decode(block, 2), 123.456 - 10.0, 1e-12);
  const std::uint16_t negative[] = {0, 0, 0xFFFF, 0xFC18};  // -1000 counts
  EXPECT_NEAR(sensor.decode(negative, 2), -1.0 - 10.0, 1e-12);
}

TEST(RegisterMap, LinearMapInvertsWithRounding) {
  const LinearMap m{0.001, 0.5};
  EXPECT_EQ(m.to_counts(0.5), 0.0);
  EXPECT_EQ(m.to_counts(1.5004), 1000.0);
  EXPECT_EQ(m.to_counts(1.5006), 1001.0);
  EXPECT_NEAR(m.to_physical(1000), 1.5, 1e-12);
}

TEST(RegisterMap, AmplifierCountsGoThroughTheGain) {
  AmplifierChannel amp;  // 0.001 V/count into a 100 V/V amplifier, 0..10 V
  amp.format = kU16;
  std::int64_t c = -1;
  EXPECT_TRUE(amp.output_to_counts(0.0, c));
  EXPECT_EQ(c, 0);
  EXPECT_TRUE(amp.output_to_counts(300.0, c));
  EXPECT_EQ(c, 3000);
  EXPECT_NEAR(amp.counts_to_output(3000), 300.0, 1e-9);
  EXPECT_TRUE(amp.output_to_counts(1000.0, c));
  EXPECT_EQ(c, 10000);
  EXPECT_TRUE(amp.output_to_counts(0.04, c));  // rounds to the nearest 0.1 V step
  EXPECT_EQ(c, 0);
  EXPECT_TRUE(amp.output_to_counts(0.06, c));
  EXPECT_EQ(c, 1);
}

TEST(RegisterMap, AmplifierSaturatesToTheModuleRangeAndSaysSo) {
  AmplifierChannel amp;
  amp.format = kU16;
  std::int64_t c = 0;
  EXPECT_FALSE(amp.output_to_counts(1500.0, c));
  EXPECT_EQ(c, 10000);
  EXPECT_FALSE(amp.output_to_counts(-50.0, c));
  EXPECT_EQ(c, 0);
  EXPECT_FALSE(amp.output_to_counts(std::numeric_limits<double>::quiet_NaN(), c));
  EXPECT_EQ(c, 0) << "NaN must command 0 V";
}

TEST(RegisterMap, AmplifierWithOffsetAndBipolarSigned16BitModule) {
  // A +-10 V module, signed 16 bit, 10 V = 32000 counts; amplifier gain 50.
  AmplifierChannel amp;
  amp.format = kS16;
  amp.gain_V_per_V = 50.0;
  amp.input_map = {10.0 / 32000.0, 0.0};
  amp.input_min_V = -10.0;
  amp.input_max_V = 10.0;
  std::int64_t c = 0;
  EXPECT_TRUE(amp.output_to_counts(250.0, c));  // 5 V in
  EXPECT_EQ(c, 16000);
  EXPECT_TRUE(amp.output_to_counts(-500.0, c));
  EXPECT_EQ(c, -32000);
  std::uint16_t regs[1];
  ASSERT_TRUE(encode_counts(c, amp.format, regs));
  EXPECT_NEAR(amp.counts_to_output(decode_counts(regs, amp.format)), -500.0, 1e-9);
  // A 4..20 mA style offset: 0 V output at 4000 counts.
  amp.format = kU16;
  amp.input_map = {10.0 / 16000.0, -2.5};
  amp.input_min_V = 0.0;
  EXPECT_TRUE(amp.output_to_counts(0.0, c));
  EXPECT_EQ(c, 4000);
}

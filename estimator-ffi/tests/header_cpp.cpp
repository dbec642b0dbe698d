// roll_estimator.h in a C++11 translation unit (estimator-ffi/tests/header_compiles.rs compiles it with
// -Wall -Wextra -Werror -pedantic -Wold-style-cast): what the header promises, checked at compile time.

#include "roll_estimator.h"
#include "roll_estimator.h"  // the include guard holds

#include <cstdint>
#include <type_traits>

// The status is returned as a 32-bit integer (the library's repr(i32)), so the C++ enum must be
// one, and the codes the C example exits with are the documented ones.
static_assert(std::is_same<std::underlying_type<rollest_status>::type, int32_t>::value, "rollest_status is int32_t");
static_assert(ROLLEST_STATUS_OK == 0, "success is 0");
static_assert(ROLLEST_STATUS_MOVED == 5, "a copied estimator's code");
static_assert(ROLLEST_STATUS_BLOB_CRC_MISMATCH == 16, "the C example's exit code for a flipped bit");

// The structs are plain C data with the sizes the interface describes: 8 KiB of storage, the
// input record's 16 floats in order (the C example copies a record into rollest_input), and ten
// estimates with four 16-bit health words.
static_assert(sizeof(rollest_estimator) == ROLLEST_ESTIMATOR_WORDS * 8, "8-byte words");
static_assert(alignof(rollest_estimator) == 8, "the storage is 8-byte aligned");
static_assert(sizeof(rollest_input) == (4 + ROLLEST_N_TAPS) * sizeof(float), "16 floats");
static_assert(sizeof(rollest_health) == 4 * sizeof(uint16_t), "four masks");
static_assert(sizeof(rollest_output) == 10 * sizeof(float) + sizeof(rollest_health), "ten estimates");
static_assert(std::is_trivially_copyable<rollest_input>::value, "plain data");
static_assert(std::is_standard_layout<rollest_output>::value, "C layout");

// The start-up check expands in C++ (no casts, C linkage of the functions it calls).
bool library_matches_header() {
    return rollest_version() == ROLLEST_VERSION && ROLLEST_ABI_OK();
}

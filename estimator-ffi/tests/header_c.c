/* roll_estimator.h in a C99 translation unit (estimator-ffi/tests/header_compiles.rs compiles it with
 * -Wall -Wextra -Werror -pedantic -Wstrict-prototypes): the oldest C the header supports. */

#include "roll_estimator.h"
#include "roll_estimator.h" /* the include guard holds */

/* The start-up check expands in C. */
int library_matches_header(void) {
    return rollest_version() == ROLLEST_VERSION && ROLLEST_ABI_OK();
}

/* The public headers compile as strict ISO C11 (-std=c11 -pedantic), not only as GNU C. */
#include <raypack.h>
#include <raypack_io.h>
#if defined(__has_include)
#if __has_include(<raypack_render.h>)
#include <raypack_render.h>
#endif
#endif

_Static_assert(_Alignof(rp_ray16) == 64, "rp_ray16 is 64-byte aligned");
_Static_assert(sizeof(rp_ray) == 48, "rp_ray keeps Embree's layout");

int rp_headers_c11_check(void);
int rp_headers_c11_check(void) { return (int)sizeof(rp_rayhit16); }

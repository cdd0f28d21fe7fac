// The doctest runner. `make -C firmware test` uses doctest's own main; PlatformIO's `pio test -e native`
// needs every test reported and the exit code left to it (docs: PlatformIO, Doctest).
#ifdef PIO_UNIT_TESTING
#define DOCTEST_CONFIG_IMPLEMENT
#include "doctest_include.h"

int main(int argc, char** argv) {
    doctest::Context context;
    context.setOption("success", true);
    context.setOption("no-exitcode", true);
    context.applyCommandLine(argc, argv);
    return context.run();
}
#else
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include "doctest_include.h"
#endif

// doctest from Debian's doctest-dev (<doctest/doctest.h>) or from PlatformIO's registry (<doctest.h>).
#pragma once
#if defined(__has_include)
#if __has_include(<doctest/doctest.h>)
#include <doctest/doctest.h>
#else
#include <doctest.h>
#endif
#else
#include <doctest/doctest.h>
#endif

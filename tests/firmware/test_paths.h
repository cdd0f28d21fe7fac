#pragma once
#include <cstdlib>
#include <string>

#ifndef SPHERE_REPO_ROOT
#define SPHERE_REPO_ROOT "."
#endif
#ifndef SPHERE_TEST_BUILD
#define SPHERE_TEST_BUILD "tests/firmware/build"
#endif

inline std::string repoPath(const std::string& rel) { return std::string(SPHERE_REPO_ROOT) + "/" + rel; }
inline std::string testBuildPath(const std::string& rel) { return std::string(SPHERE_TEST_BUILD) + "/" + rel; }

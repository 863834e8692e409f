// The subcommands of the `kdspace` command. Each takes the words after its name and returns the exit
// code: 0 success, 2 usage error, 1 bad data or I/O error (messages already printed to stderr).
#pragma once

#include <string>
#include <vector>

int run_knn_command(const std::vector<std::string>& args);     // knn_command.cpp
int run_radius_command(const std::vector<std::string>& args);  // knn_command.cpp
int run_demo_command(const std::vector<std::string>& args);    // demo_command.cpp
int run_rays_command(const std::vector<std::string>& args);    // rays_command.cpp
int run_render_command(const std::vector<std::string>& args);  // rays_command.cpp
int run_pairs_command(const std::vector<std::string>& args);   // joins_command.cpp
int run_count_command(const std::vector<std::string>& args);   // joins_command.cpp
int run_index_command(const std::vector<std::string>& args);   // index_command.cpp
int run_overlaps_command(const std::vector<std::string>& args);  // overlaps_command.cpp

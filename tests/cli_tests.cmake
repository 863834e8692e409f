# The kdspace command: exit codes, messages, outputs (tests/cli_tests.sh; needs bash and python3).
add_test(NAME cli COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/cli_tests.sh $<TARGET_FILE:kdspace_cli> ${CMAKE_CURRENT_BINARY_DIR}/cli-scratch)
# 1,000 random corruptions of index files: each a clear error, exit 1 (tests/index_corruption_tests.sh).
add_test(NAME cli_index_corruption
  COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/index_corruption_tests.sh $<TARGET_FILE:kdspace_cli> ${CMAKE_CURRENT_BINARY_DIR}/index-corruption-scratch)

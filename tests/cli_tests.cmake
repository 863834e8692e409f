# The kdspace command: exit codes, messages, outputs (tests/cli_tests.sh; needs bash and python3).
add_test(NAME cli COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/cli_tests.sh $<TARGET_FILE:kdspace_cli> ${CMAKE_CURRENT_BINARY_DIR}/cli-scratch)
# 1,000 random corruptions of index files: each a clear error, exit 1 (tests/index_corruption_tests.sh).
# Under the sanitizers 200 of them: each run of the command there costs some 30 times a release run
# (106 s for 1,000 against 3.5 s, measured), and the release run has already tried all 1,000.
if(KDSPACE_SANITIZE OR KDSPACE_TSAN)
  set(KDSPACE_CORRUPTION_TRIALS 200)
else()
  set(KDSPACE_CORRUPTION_TRIALS 1000)
endif()
add_test(NAME cli_index_corruption
  COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/index_corruption_tests.sh $<TARGET_FILE:kdspace_cli>
          ${CMAKE_CURRENT_BINARY_DIR}/index-corruption-scratch ${KDSPACE_CORRUPTION_TRIALS})

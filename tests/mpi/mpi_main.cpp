// The main of the MPI tests: Catch2 on every rank, between MPI_Init and MPI_Finalize. Every rank
// runs the same test cases in the same order; the exit code is the worst of all ranks.
#define CATCH_CONFIG_RUNNER
#include <mpi.h>

#include <catch2/catch.hpp>

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  const int code = Catch::Session().run(argc, argv);
  int worst = code;
  MPI_Allreduce(&code, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  MPI_Finalize();
  return worst;
}

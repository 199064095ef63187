#include "client/cmd/client_bench_commands.h"

int main(int argc, char** argv) {
  return vistream::runClientBenchTool(argc, argv);
}

#include "server/cmd/pvs_commands.h"

int main(int argc, char** argv) {
  return vistream::runPvsTool(argc, argv);
}

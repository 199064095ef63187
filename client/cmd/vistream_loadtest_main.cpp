#include "client/cmd/loadtest_commands.h"

int main(int argc, char** argv) {
  return vistream::runLoadTestTool(argc, argv);
}

#include "server/cmd/server_commands.h"

int main(int argc, char** argv) {
  return vistream::runServerTool(argc, argv);
}

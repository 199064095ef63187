#include "client/cmd/client_commands.h"

int main(int argc, char** argv) {
  return vistream::runClientTool(argc, argv);
}

#include "common/cmd/scene_commands.h"

int main(int argc, char** argv) {
  return vistream::runSceneTool(argc, argv);
}

#!/usr/bin/env python3
"""Tests .ci/check_layering.py on small fake trees whose violations are known:
each case writes a few files, runs the check as CI does and compares the
reported `path:line` pairs with the ones planted."""

import os
import re
import subprocess
import sys
import tempfile
import unittest

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", ".ci",
                      "check_layering.py")

# A tree where every include goes down or sideways inside a layer: each
# folder of the order has one header.
CLEAN_TREE = {
    "common/core/check.h": "#pragma once\n#include <vector>\n",
    "common/scene/scene.h": '#pragma once\n#include "common/core/check.h"\n',
    "common/spatial/kdtree.h": '#pragma once\n#include "common/scene/scene.h"\n',
    "common/raycast/ray_query.h": '#pragma once\n#include "common/spatial/kdtree.h"\n',
    "common/world/free_space.h": '#pragma once\n#include "common/raycast/ray_query.h"\n',
    "common/generate/path.h": '#pragma once\n#include "common/world/free_space.h"\n',
    "common/cmd/cli.h": '#pragma once\n#include "common/generate/path.h"\n',
    "protocol/wire/framing.h": '#pragma once\n#include "common/cmd/cli.h"\n#include "vistream_generated.h"\n',
    "server/stream/session.h": '#pragma once\n#include "protocol/wire/framing.h"\n#include "common/world/free_space.h"\n',
    "server/stream/session.cpp": '#include "session.h"\n',
    "client/net/stream_client.h": '#pragma once\n#include "protocol/wire/framing.h"\n#include "common/cmd/cli.h"\n',
}


def run_check(files):
    """Writes the files into a fresh root, runs the check; returns
    (exit status, set of (path, line) reported, stdout)."""
    with tempfile.TemporaryDirectory() as root:
        for rel, text in files.items():
            path = os.path.join(root, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w", encoding="utf-8") as out:
                out.write(text)
        result = subprocess.run([sys.executable, SCRIPT, "--root", root],
                                capture_output=True, text=True, check=False)
    if result.returncode not in (0, 1) or "Traceback" in result.stderr:
        raise AssertionError(f"the check crashed:\n{result.stderr}")
    reported = set()
    for line in result.stdout.splitlines():
        match = re.match(r"^(\S+):(\d+): error: ", line)
        if match:
            reported.add((match.group(1), int(match.group(2))))
    return result.returncode, reported, result.stdout


def with_files(extra):
    files = dict(CLEAN_TREE)
    files.update(extra)
    return files


class CheckLayering(unittest.TestCase):
    def test_a_tree_whose_includes_all_go_down_passes(self):
        status, reported, _ = run_check(CLEAN_TREE)
        self.assertEqual(status, 0)
        self.assertEqual(reported, set())

    def test_spatial_including_raycast_is_reported_with_its_file_and_line(self):
        status, reported, out = run_check(with_files({
            "common/spatial/kdtree.cpp":
                '#include "common/spatial/kdtree.h"\n\n#include "common/raycast/ray_query.h"\n'}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("common/spatial/kdtree.cpp", 3)})
        self.assertIn("common/spatial/ may not include common/raycast/", out)

    def test_every_upward_include_inside_common_is_reported(self):
        # core is the bottom and cmd the top: core including each higher folder
        # breaks the order once per line.
        higher = ["scene/scene.h", "spatial/kdtree.h", "raycast/ray_query.h",
                  "world/free_space.h", "generate/path.h", "cmd/cli.h"]
        text = "".join(f'#include "common/{h}"\n' for h in higher)
        status, reported, _ = run_check(with_files({"common/core/log.h": text}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("common/core/log.h", n) for n in range(1, 7)})

    def test_an_upward_include_written_relative_to_the_file_is_reported(self):
        status, reported, _ = run_check(with_files({
            "common/scene/scene.cpp": '#include "scene.h"\n#include "../world/free_space.h"\n'}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("common/scene/scene.cpp", 2)})

    def test_an_angled_include_is_checked_like_a_quoted_one(self):
        status, reported, _ = run_check(with_files({
            "common/raycast/embree.cpp": "#include <common/generate/path.h>\n"}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("common/raycast/embree.cpp", 1)})

    def test_common_including_protocol_or_protocol_including_server_is_reported(self):
        status, reported, out = run_check(with_files({
            "common/cmd/scene_commands.cpp": '#include "protocol/wire/framing.h"\n',
            "protocol/wire/framing.cpp": '#include "framing.h"\n#include "server/stream/session.h"\n'}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("common/cmd/scene_commands.cpp", 1),
                                    ("protocol/wire/framing.cpp", 2)})
        self.assertIn("common/ may not include protocol/", out)

    def test_server_and_client_including_each_other_are_both_reported(self):
        status, reported, _ = run_check(with_files({
            "server/stream/session.cpp": '#include "session.h"\n#include "client/net/stream_client.h"\n',
            "client/net/stream_client.cpp": '#include "server/stream/session.h"\n'}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("server/stream/session.cpp", 2),
                                    ("client/net/stream_client.cpp", 1)})

    def test_a_folder_of_common_outside_the_order_is_reported(self):
        status, reported, out = run_check(with_files({
            "common/misc/util.h": '#pragma once\n#include "common/core/check.h"\n'}))
        self.assertEqual(status, 1)
        self.assertEqual(reported, {("common/misc/util.h", 1)})
        self.assertIn("common/misc/ has no place", out)

    def test_includes_in_comments_after_code_and_of_unknown_headers_are_not_violations(self):
        status, reported, _ = run_check(with_files({
            "common/core/view.h": ('#pragma once\n// #include "common/cmd/cli.h"\n'
                                   '#include "pvs_database_generated.h"\n#include <glm/glm.hpp>\n')}))
        self.assertEqual(status, 0)
        self.assertEqual(reported, set())

    def test_a_root_without_common_is_a_usage_error(self):
        with tempfile.TemporaryDirectory() as root:
            result = subprocess.run([sys.executable, SCRIPT, "--root", root],
                                    capture_output=True, text=True, check=False)
        self.assertEqual(result.returncode, 2)
        self.assertIn("no common/ folder", result.stderr)


if __name__ == "__main__":
    unittest.main()

#!/usr/bin/env python3
"""Checks that #include lines follow the project's one-way layering.

Across code folders:  common < protocol < server, client
  (server and client never include each other).
Inside common/:       core < scene < spatial < raycast < world < light < avatar < impostor < generate < cmd

A file may include files of its own layer or of a lower one, never of a higher
one. Every include of a file under common/, protocol/, server/ and client/ is
checked, quoted or angled, written from the repository root
("common/scene/scene.h") or relative to the including file ("scene.h",
"../core/check.h"). Includes that name no file of these folders (system and
generated headers) are not checked. A folder under common/ that is not in the
order is an error, so a new folder gets a place in the order when it is made.

Usage: check_layering.py [--root DIR]   (default: the repository holding this
script). Prints one line per violation, `path:line: ...`, and exits 1 if there
is any, 0 otherwise; exit 2 for a root that is not a vistream tree.
"""

import argparse
import os
import re
import sys

# Folders in dependency order; a folder may include the folders listed for it
# (and itself).
FOLDER_MAY_INCLUDE = {
    "common": {"common"},
    "protocol": {"common", "protocol"},
    "server": {"common", "protocol", "server"},
    "client": {"common", "protocol", "client"},
}
FOLDER_ORDER_TEXT = "common < protocol < server, client (server and client never include each other)"

COMMON_ORDER = ["core", "scene", "spatial", "raycast", "world", "light", "avatar", "impostor", "generate", "cmd"]
COMMON_ORDER_TEXT = " < ".join(COMMON_ORDER)

SOURCE_SUFFIXES = (".h", ".hpp", ".cpp", ".cc", ".inl")
INCLUDE_RE = re.compile(r'^\s*#\s*include\s*(?:"([^"]+)"|<([^>]+)>)')


def layer_of(rel_path):
    """(folder, common sub-folder or None) of a path relative to the root,
    or None when the path lies outside the checked folders."""
    parts = rel_path.split("/")
    if not parts or parts[0] not in FOLDER_MAY_INCLUDE:
        return None
    if parts[0] == "common" and len(parts) > 2:
        return ("common", parts[1])
    return (parts[0], None)


def resolve(root, including_rel, target, quoted):
    """Path of the included file relative to the root, or None when the
    include names no file of the checked folders."""
    candidates = []
    if quoted:
        base = os.path.dirname(including_rel)
        candidates.append(os.path.normpath(os.path.join(base, target)))
    candidates.append(os.path.normpath(target))
    for candidate in candidates:
        candidate = candidate.replace(os.sep, "/")
        if candidate.startswith("../") or layer_of(candidate) is None:
            continue
        if os.path.isfile(os.path.join(root, candidate)):
            return candidate
    # A root-relative include of a file that does not exist (yet) is still
    # checked by its folder names, so a typo cannot hide a violation.
    target = os.path.normpath(target).replace(os.sep, "/")
    if layer_of(target) is not None:
        return target
    return None


def violation(from_layer, to_layer):
    """Why an include from one layer to another breaks the order, or None."""
    from_folder, from_sub = from_layer
    to_folder, to_sub = to_layer
    if to_folder not in FOLDER_MAY_INCLUDE[from_folder]:
        return f"{from_folder}/ may not include {to_folder}/ (order: {FOLDER_ORDER_TEXT})"
    if from_folder == "common" and to_folder == "common":
        if to_sub is None or from_sub is None:
            return None
        if from_sub == to_sub or from_sub not in COMMON_ORDER:
            return None  # a folder outside the order is reported once, by file
        if to_sub not in COMMON_ORDER:
            return f"common/{to_sub}/ has no place in common's order ({COMMON_ORDER_TEXT})"
        if COMMON_ORDER.index(to_sub) > COMMON_ORDER.index(from_sub):
            return (f"common/{from_sub}/ may not include common/{to_sub}/ "
                    f"(order inside common/: {COMMON_ORDER_TEXT})")
    return None


def source_files(root):
    for folder in sorted(FOLDER_MAY_INCLUDE):
        top = os.path.join(root, folder)
        for directory, subdirs, files in os.walk(top):
            subdirs.sort()
            for name in sorted(files):
                if name.endswith(SOURCE_SUFFIXES):
                    path = os.path.join(directory, name)
                    yield os.path.relpath(path, root).replace(os.sep, "/")


def check(root):
    """List of (path, line, message) for every include against the order,
    and the number of files and includes read."""
    problems = []
    files = includes = 0
    for rel in source_files(root):
        files += 1
        layer = layer_of(rel)
        if layer[0] == "common" and layer[1] is not None and layer[1] not in COMMON_ORDER:
            problems.append((rel, 1, f"common/{layer[1]}/ has no place in common's order "
                                     f"({COMMON_ORDER_TEXT}); add it to .ci/check_layering.py"))
        with open(os.path.join(root, rel), encoding="utf-8", errors="replace") as source:
            for number, line in enumerate(source, start=1):
                match = INCLUDE_RE.match(line)
                if not match:
                    continue
                quoted = match.group(1) is not None
                target = match.group(1) if quoted else match.group(2)
                resolved = resolve(root, rel, target, quoted)
                if resolved is None:
                    continue
                includes += 1
                why = violation(layer, layer_of(resolved))
                if why:
                    problems.append((rel, number, f'includes "{target}": {why}'))
    return problems, files, includes


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser.add_argument("--root", default=default_root,
                        help="repository root (default: %(default)s)")
    args = parser.parse_args(argv)
    root = os.path.abspath(args.root)
    if not os.path.isdir(os.path.join(root, "common")):
        print(f"check_layering: error: {root} has no common/ folder", file=sys.stderr)
        return 2
    problems, files, includes = check(root)
    for path, number, message in problems:
        print(f"{path}:{number}: error: {message}")
    if problems:
        print(f"check_layering: {len(problems)} includes break the layering "
              f"({files} files, {includes} includes read)", file=sys.stderr)
        return 1
    print(f"check_layering: layering holds ({files} files, {includes} includes read)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

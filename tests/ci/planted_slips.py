"""What the deploy checks share: a list of problems that a condition adds to,
and the test that plants one slip at a time in a copy of the checked files."""

import os
import shutil
import tempfile


class Problems(list):
    """Problems found so far; need() adds `text` when `condition` fails."""

    def need(self, condition, text):
        if not condition:
            self.append(text)
        return condition


def run_slips(tool, check, source, slips):
    """Copies `source` (a folder) once per slip, replaces the slip's text in
    its file (a path under `source`), and expects check(copy) to report a
    problem containing the slip's words; check(source) itself must pass.
    `slips`: [(file, old, new, words)]. Prints a line per failure and a
    summary; returns the exit code."""
    failures = []
    clean = check(source)
    if clean:
        failures.append(f"the files as they are fail: {clean}")
    for name, old, new, words in slips:
        with tempfile.TemporaryDirectory() as d:
            copy = os.path.join(d, "copy")
            shutil.copytree(source, copy)
            path = os.path.join(copy, name)
            with open(path, encoding="utf-8") as f:
                text = f.read()
            if old not in text:
                failures.append(f"{name}: the slip's text {old!r} is not in the file")
                continue
            with open(path, "w", encoding="utf-8") as f:
                f.write(text.replace(old, new, 1))
            problems = check(copy)
            if not any(words in p for p in problems):
                failures.append(f"{name}: {old!r} -> {new!r} not reported as {words!r}: {problems}")
    for f in failures:
        print(f"{tool}: {f}")
    print(f"{tool}: {len(slips) - len(failures)} of {len(slips)} slips named")
    return 1 if failures else 0

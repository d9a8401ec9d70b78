"""Build the course website from the committed notebooks: ``make book`` (output in build/book/html).

The chapters are rendered as committed (strict nbval has checked those outputs); nothing is
executed and nothing is downloaded. Sphinx needs its sources in one folder, so this script
stages ``book/`` (configuration and landing page) with ``notebooks/*.ipynb`` in build/book_src and
builds from there. Open build/book/html/index.html, or serve the folder:
``python -m http.server -d build/book/html``.

The one change to the staged copies: a notebook's saved quiz shows its questions without answers
(students should answer first), so on the site each quiz output shows the quiz file's questions
with their answers and feedback instead, under "Questions and answers" (``Quiz.answers_html``).
"""

from __future__ import annotations

import fcntl
import glob
import json
import os
import shutil
import sys
import time

from course_helpers.notebook.quiz import METADATA_KEY, Quiz

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STAGE = os.path.join(REPO, "build", "book_src")
OUTPUT = os.path.join(REPO, "build", "book", "html")


def stage() -> list[str]:
    """Copy the site's sources into STAGE; return the chapters, in order."""
    shutil.rmtree(STAGE, ignore_errors=True)
    shutil.copytree(os.path.join(REPO, "book"), STAGE)
    chapters = sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
    for path in chapters:
        with open(path, encoding="utf-8") as handle:
            notebook = json.load(handle)
        with_answers(notebook)
        with open(os.path.join(STAGE, os.path.basename(path)), "w", encoding="utf-8") as handle:
            json.dump(notebook, handle, indent=1, ensure_ascii=False)
    return [os.path.basename(p) for p in chapters]


def with_answers(notebook: dict) -> list[str]:
    """Show the answers in every quiz output of ``notebook`` (in place); return the quizzes' names."""
    names = []
    for cell in notebook["cells"]:
        for output in cell.get("outputs", []):
            name = output.get("metadata", {}).get(METADATA_KEY, {}).get("quiz")
            if name:
                output["data"] = {"text/html": Quiz.load(name).answers_html(),
                                  "text/plain": output["data"]["text/plain"]}
                names.append(name)
    return names


def main() -> int:
    from sphinx.cmd.build import build_main

    started = time.monotonic()
    os.makedirs(os.path.join(REPO, "build"), exist_ok=True)
    # one build at a time: two builds would delete each other's staged sources
    lock = open(os.path.join(REPO, "build", ".book.lock"), "w")  # noqa: SIM115 (held until exit)
    fcntl.flock(lock, fcntl.LOCK_EX)
    chapters = stage()
    print(f"building the site from {len(chapters)} notebooks ...", flush=True)
    shutil.rmtree(os.path.dirname(OUTPUT), ignore_errors=True)
    # -W: a warning (a broken reference, a missing page) fails the build; -q: only problems are printed
    code = build_main(["-b", "html", "-q", "-W", "--keep-going", "-d",
                       os.path.join(REPO, "build", "book_doctrees"), STAGE, OUTPUT])
    if code == 0:
        print(f"site built in {time.monotonic() - started:.0f} s: {os.path.join(OUTPUT, 'index.html')}")
    return code


if __name__ == "__main__":
    sys.exit(main())

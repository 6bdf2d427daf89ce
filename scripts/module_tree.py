"""Prints the module tree of planner-core and server, each file with the
first line of its `//!` doc, and with --update rewrites the tree at the end
of ARCHITECTURE.md (everything after the "generated" line's blank line).
Usage: python3 scripts/module_tree.py [--update]"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CRATES = [("planner-core/src", "planner-core"), ("server/src", "server")]
# Test-only files are left out of the map.
SKIP = ("tests.rs", "test_support.rs", "testing.rs", "test_rng.rs")


def first_doc(path, width=72):
    """The first sentence of the file's `//!` doc, shortened to `width`."""
    lines = []
    for line in path.read_text().splitlines():
        if not line.startswith("//!"):
            break
        text = line[3:].strip()
        if not text:
            if lines:
                break
            continue
        lines.append(text)
    doc = " ".join(lines)
    end = doc.find(". ")
    doc = doc if end < 0 else doc[: end + 1]
    return doc if len(doc) <= width else doc[: width - 1].rstrip() + "…"


def tree():
    out = []
    for folder, name in CRATES:
        base = ROOT / folder
        out.append(f"{name}/src/")
        shown = set()
        for path in sorted(base.rglob("*.rs"), key=lambda p: p.relative_to(base).parts):
            if path.name in SKIP:
                continue
            rel = path.relative_to(base)
            for depth in range(1, len(rel.parts)):
                folder_part = rel.parts[:depth]
                if folder_part not in shown:
                    shown.add(folder_part)
                    out.append(f"{'  ' * depth}{folder_part[-1]}/")
            label = f"{'  ' * len(rel.parts)}{rel.name}"
            doc = first_doc(path)
            out.append(f"{label:<26} {doc}" if doc else label)
    return "\n".join(out)


def main():
    text = "```\n" + tree() + "\n```\n"
    if "--update" not in sys.argv:
        print(text, end="")
        return
    doc = ROOT / "ARCHITECTURE.md"
    head = doc.read_text()
    marker = "(`python3 scripts/module_tree.py --update`):\n"
    cut = head.index(marker) + len(marker)
    doc.write_text(head[:cut] + "\n" + text)


if __name__ == "__main__":
    main()

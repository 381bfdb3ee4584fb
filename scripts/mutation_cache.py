"""Read mutmut 2's cache of one scripts/mutation.sh scratch copy (read only, safe mid-run).

    python scripts/mutation_cache.py report DIR [DIR ...]    # one table row per module
    python scripts/mutation_cache.py show DIR [STATUS]       # each mutant's changed line

DIR is out/mutation/<module>/ (holding .mutmut-cache, MODULE, TESTS, SECONDS).  ``show``
applies each mutant to the module as committed (``git show HEAD:MODULE``), never to the
scratch file, which holds the mutant under test while a run is going; unlike `mutmut
show`, it does not re-map mutmut's line records (that kills a running `mutmut run`).
STATUS: bad_survived (default), bad_timeout, ok_killed, ok_suspicious, untested.
"""
import sqlite3
import subprocess
import sys
from pathlib import Path


def counts(work: Path, module: str) -> dict:
    db = sqlite3.connect(work / ".mutmut-cache")
    return dict(db.execute(
        "select Mutant.status, count(*) from Mutant join Line on Mutant.line = Line.id "
        "join SourceFile on Line.sourcefile = SourceFile.id where SourceFile.filename = ? "
        "group by 1", (module,)).fetchall())


def report(dirs: list[Path]) -> None:
    print("| module | tests | mutants | killed | survived | timeout | untested "
          "| score ((killed + timeout) / tested) | run time |")
    print("|---|---|---|---|---|---|---|---|---|")
    for work in dirs:
        module = (work / "MODULE").read_text().strip()
        tests = (work / "TESTS").read_text().strip()
        seconds = int((work / "SECONDS").read_text())
        n = counts(work, module)
        # "suspicious" = killed, but slowly; a timeout (e.g. an endless loop) is detected
        killed = n.get("ok_killed", 0) + n.get("ok_suspicious", 0)
        survived, timeout = n.get("bad_survived", 0), n.get("bad_timeout", 0)
        tested = killed + survived + timeout
        score = f"{100 * (killed + timeout) / tested:.0f} %" if tested else "-"
        print(f"| `{module.removeprefix('mi_displace/')}` | `{tests}` | {sum(n.values())} "
              f"| {killed} | {survived} | {timeout} | {n.get('untested', 0)} | {score} "
              f"| {seconds // 60} min |")


def show(work: Path, status: str) -> None:
    from mutmut import Context, RelativeMutationID, mutate

    module = (work / "MODULE").read_text().strip()
    source = subprocess.run(["git", "show", f"HEAD:{module}"], check=True, capture_output=True,
                            text=True).stdout
    db = sqlite3.connect(work / ".mutmut-cache")
    rows = db.execute(
        "select Mutant.id, Line.line, Line.line_number, Mutant.`index` from Mutant join Line "
        "on Mutant.line = Line.id join SourceFile on Line.sourcefile = SourceFile.id "
        "where SourceFile.filename = ? and Mutant.status = ? "
        "order by Line.line_number, Mutant.`index`", (module, status)).fetchall()
    old = source.split("\n")
    for pk, line, number, index in rows:
        mid = RelativeMutationID(line=line, index=index, line_number=number)
        new = mutate(Context(source=source, mutation_id=mid, filename=module))[0].split("\n")
        if len(new) != len(old):
            print(f"#{pk} L{number + 1}: {line.strip()}\n    -> (line removed)")
            continue
        for i, (a, b) in enumerate(zip(old, new)):
            if a != b:
                print(f"#{pk} L{i + 1}: {a.strip()}\n    -> {b.strip()}")


if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] not in ("report", "show"):
        sys.exit(__doc__)
    if sys.argv[1] == "report":
        report([Path(d) for d in sys.argv[2:]])
    else:
        show(Path(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else "bad_survived")

"""Read mutmut 2's cache of one scripts/mutation.sh scratch copy (read only, safe mid-run).

    python scripts/mutation_cache.py report DIR [DIR ...]    # one table row per module
    python scripts/mutation_cache.py show DIR [STATUS]       # each mutant's changed line
    python scripts/mutation_cache.py register DIR            # all mutants, untested
    python scripts/mutation_cache.py sample DIR N SEED       # write DIR/SAMPLE

DIR is out/mutation/<module>/ (holding .mutmut-cache, MODULE, TESTS, SECONDS and, for a
sampled module, SAMPLE).  ``show`` applies each mutant to the module as committed (``git
show HEAD:MODULE``), never to the scratch file, which holds the mutant under test while a
run is going; unlike `mutmut show`, it does not re-map mutmut's line records (that kills a
running `mutmut run`).  STATUS: bad_survived (default), bad_timeout, ok_killed,
ok_suspicious, untested.

``register`` (run before any mutant, never during a run) lists the module's mutants into
the cache as `mutmut run` does before testing (the same Line and Mutant records, so that
`mutmut run ID` finds them) without running anything.  ``sample`` writes the first N ids
of a permutation of all the module's mutants drawn with SEED (Python's random.Random):
a larger N with the same seed extends the sample, keeping the mutants already drawn, so
every drawn mutant was drawn uniformly at random from the whole module.
"""
import math
import os
import random
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


def mutant_ids(work: Path, module: str) -> list[int]:
    db = sqlite3.connect(work / ".mutmut-cache")
    return [r[0] for r in db.execute(
        "select Mutant.id from Mutant join Line on Mutant.line = Line.id join SourceFile on "
        "Line.sourcefile = SourceFile.id where SourceFile.filename = ? order by Mutant.id",
        (module,))]


def register(work: Path) -> None:
    from mutmut import add_mutations_by_file
    from mutmut.cache import update_line_numbers

    module = (work / "MODULE").read_text().strip()
    os.chdir(work)  # mutmut's cache is .mutmut-cache in the working directory
    update_line_numbers(module)
    # dict_synonyms [""] and config None: the defaults of `mutmut run` (every mutation type)
    add_mutations_by_file({}, module, [""], None)


def sample(work: Path, n: int, seed: int) -> None:
    ids = mutant_ids(work, (work / "MODULE").read_text().strip())
    drawn = random.Random(seed).sample(ids, len(ids))[:n]
    (work / "SAMPLE").write_text(f"seed {seed}\n" + "\n".join(map(str, drawn)) + "\n")


def read_sample(work: Path) -> tuple[int, list[int]] | None:
    if not (work / "SAMPLE").exists():
        return None
    head, *ids = (work / "SAMPLE").read_text().split("\n")
    return int(head.split()[1]), [int(i) for i in ids if i]


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval (95 % for z = 1.96) of a proportion k / n, n > 0."""
    p, d = k / n, 1 + z * z / n
    centre = (p + z * z / (2 * n)) / d
    half = z / d * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def sample_report(dirs: list[Path]) -> None:
    print("| module | tests | mutants (total) | sampled (seed) | killed | survived | timeout "
          "| untested | score on the sample | Wilson 95 % | run time |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for work in dirs:
        module = (work / "MODULE").read_text().strip()
        seed, ids = read_sample(work)
        db = sqlite3.connect(work / ".mutmut-cache")
        status = dict(db.execute(f"select id, status from Mutant where id in "
                                 f"({','.join(map(str, ids)) or 'null'})").fetchall())
        # a drawn mutant of a line that a later commit changed is gone from the cache
        # (mutmut re-maps its lines on --resume): counted apart, not as tested
        n = {"gone": 0}
        for i in ids:
            n[status.get(i, "gone")] = n.get(status.get(i, "gone"), 0) + 1
        killed = n.get("ok_killed", 0) + n.get("ok_suspicious", 0)
        survived, timeout = n.get("bad_survived", 0), n.get("bad_timeout", 0)
        tested = killed + survived + timeout
        score, interval = "-", "-"
        if tested:
            lo, hi = wilson(killed + timeout, tested)
            score = f"{100 * (killed + timeout) / tested:.0f} % of {tested}"
            interval = f"{100 * lo:.0f}–{100 * hi:.0f} %"
        seconds = int((work / "SECONDS").read_text())
        gone = f"; {n['gone']} gone" if n["gone"] else ""
        print(f"| `{module.removeprefix('mi_displace/')}` | `{(work / 'TESTS').read_text().strip()}` "
              f"| {len(mutant_ids(work, module))} | {len(ids)} ({seed}"
              f"{gone}) | {killed} | {survived} "
              f"| {timeout} | {n.get('untested', 0)} | {score} | {interval} | {seconds // 60} min |")


def report(dirs: list[Path]) -> None:
    sampled = [d for d in dirs if (d / "SAMPLE").exists()]
    if sampled:
        sample_report(sampled)
        print()
    dirs = [d for d in dirs if d not in sampled]
    if not dirs:
        return
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
    command = sys.argv[1] if len(sys.argv) > 2 else None
    if command == "report":
        report([Path(d) for d in sys.argv[2:]])
    elif command == "show":
        show(Path(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else "bad_survived")
    elif command == "register":
        register(Path(sys.argv[2]))
    elif command == "sample" and len(sys.argv) == 5:
        sample(Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
    else:
        sys.exit(__doc__)

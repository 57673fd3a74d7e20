"""Benchmark of numba's cold start in ``hcid run configs/ci.yaml`` (``make bench``).

Every run is a subprocess with ``NUMBA_CACHE_DIR`` set to a fresh temporary
folder (numba reads it when it is imported, so only a new process honours it)
and a fresh temporary run directory; the repository's own caches are never
read or written.

First a cold ``hcid run --jobs 1`` in a child process that listens to numba's
``numba:compile`` events: ``--jobs 1`` runs every task in that process, where
the listener is (``--jobs 2`` forks workers, whose compiles it would not
see), and where the engine's two parts, which ``hcid run`` compiles at once
in this process and a forked child, are compiled one after the other first
(``hcid.arx.engine.compile_kernels``), so that every kernel's compile is seen.
The events nest (compiling a kernel compiles the kernels it calls, and
numba's implementations of numpy functions it uses), so each function gets
its inclusive seconds and its exclusive (self) seconds, the inclusive minus
its nested compiles'; the exclusive seconds add up to the run's compile time.
numba's intrinsics (``hcid.arx._lane_ir``'s ``@intrinsic``) and the parallel
loops of a ``parallel=True`` kernel are no dispatchers: their time is their
caller's. A compile fires no event for writing its cache entry, so a nested
kernel's write counts in its caller's exclusive time. After the run the
child marks each compiled signature of hcid as used or not: reachable from
a compile for a call from Python through the call types of the callers'
final typings. An unused one was compiled for argument types of an early
typing pass only (``Literal[int](0)`` for a variable that starts at 0). The
same child then runs warm on that cache, where a compile event means a
kernel the cache missed.

A third recorded ``hcid run --jobs 1`` starts from a fresh cache into which
the install step's warm-up (:data:`WARM_UP`, the line of the Makefile's
install recipe) has compiled the engine's kernels: the first run of a fresh
install, whose compile events are what the warm-up leaves to it.

Then the wall times from the plain ``hcid`` command, alternating: cold with
``--jobs 2`` (the default), warm on that cache, cold with ``--jobs 1``, and
"installed" (``--jobs 2`` on a fresh cache after the warm-up, which is timed
apart); beside each, the CPU seconds of the command and its workers.
``--json`` writes everything, to compare two commits.

The numba cache is the only thing made cold: hcid's own bytecode (``.pyc``),
which a fresh editable install also lacks, is the checkout's, already written.

``--smoke``: one round, and every run after the first recorded (cold) one
starts from a copy of its cache, so that all paths of this script run in
about half a minute; its cold and installed figures after the first are then
warm, and say so.

Run: ``.venv/bin/python benchmarks/cold_start.py [--repeat N] [--smoke]`` from the project root. This
process imports nothing from hcid or numba; the children do the work.
"""

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: The checkout of hcid measured (``--source``; this one by default): the children run in it,
#: with it first on their path.
SOURCE = ROOT
#: Kernel groups, by the module that defines the jitted function; everything else is "other".
GROUPS = (
    "hcid.arx._lanes",
    "hcid.arx._kernels",
    "hcid.arx._blocks",
    "hcid.arx._lane_ir",
    "hcid.loop.simulate",
)
OTHER = "other"
TOP_FUNCTIONS = 40
#: The install step's warm-up, as the Makefile's install recipe runs it (``python -c``, with
#: ``OPENBLAS_NUM_THREADS=1``): the engine's kernels compiled into numba's cache.
WARM_UP = "from hcid.pipeline.parallel import compile_before_fork as c; c()"
#: argv[1] of the recording child, this file run as ``cold_start.py --child OUT HCID_ARGS...``.
CHILD = "--child"


# --------------------------------------------------------------------------- the recording child


def _child(out: str, hcid_args: list[str]) -> None:
    """Run ``hcid HCID_ARGS`` in this process with a compile listener; write what it saw to OUT."""
    start = time.perf_counter()
    import importlib.util

    from numba.core import event

    package = importlib.util.find_spec("hcid").submodule_search_locations[0]
    event.Listener.register(_CompileRecorder)  # register() checks isinstance(listener, Listener)
    listener = _CompileRecorder(start, package)
    event.register("numba:compile", listener)

    import numba
    from numba.core.registry import CPUDispatcher

    import hcid.cli

    # hcid run compiles the engine's two parts at once, one in a forked child this listener
    # cannot see (hcid.pipeline.parallel.compile_before_fork): here one after the other, so that the
    # table holds every kernel. An hcid from before that has neither.
    try:
        import hcid.pipeline.parallel as parallel
        from hcid.arx.engine import KERNEL_PARTS, compile_kernels
    except ImportError:
        pass
    else:
        for part in KERNEL_PARTS:
            compile_kernels(part)
        parallel._compiled = True

    sys.argv = ["hcid", *hcid_args]
    try:
        hcid.cli.main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    wall = time.perf_counter() - start
    event.unregister("numba:compile", listener)
    listener.mark_used()

    # Every jitted function of hcid, compiled or loaded from the cache in this run.
    loaded = {}
    for name, module in list(sys.modules.items()):
        if name == "hcid" or name.startswith("hcid."):
            for value in vars(module).values():
                if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                    stats = value.stats
                    loaded[_name(value.py_func)] = {
                        "signatures": len(value.overloads),
                        "cache_hits": sum(stats.cache_hits.values()),
                        "cache_misses": sum(stats.cache_misses.values()),
                    }
    result = {
        "exit_code": code,
        "wall_s": wall,
        "numba": numba.__version__,
        "numba_cache_dir": numba.config.CACHE_DIR,
        "functions": listener.functions(),
        "dispatchers": loaded,
    }
    Path(out).write_text(json.dumps(result, indent=1))
    sys.exit(code)


def _name(func) -> str:
    return f"{func.__module__}.{func.__qualname__}"


class _CompileRecorder:
    """Inclusive and exclusive seconds of every compile event, per function and signature.

    A numba event listener. A stack of the compiles in progress: a compile's
    seconds are taken out of its parent's exclusive time. Each function also
    keeps where it was first compiled from (the compile that needed it, or the
    hcid function that called it) and whether a compile happened while a
    module was being imported.
    """

    def __init__(self, start: float, package: str):
        self._start = start
        self._package = package
        self._stack = []  # [name, start, seconds of nested compiles]
        self._functions = {}
        self._dispatchers = {}  # name -> the dispatchers of that name (closures may share one)

    def notify(self, ev):
        if ev.is_start:
            self.on_start(ev)
        else:
            self.on_end(ev)

    def on_start(self, ev):
        dispatcher = ev.data["dispatcher"]
        name = _name(dispatcher.py_func)
        now = time.perf_counter()
        record = self._functions.get(name)
        if record is None:
            record = self._functions[name] = {
                "module": dispatcher.py_func.__module__,
                "qualname": dispatcher.py_func.__qualname__,
                "parallel": bool(dispatcher.targetoptions.get("parallel")),
                "signatures": [],
                "failed": 0,
                "self_s": 0.0,
                "inclusive_s": 0.0,
                "first_at_s": now - self._start,
                "first_from": self._stack[-1][0] if self._stack else self._caller(),
                "at_import": 0,
                "at_call": 0,
            }
        record["at_import" if self._importing() else "at_call"] += 1
        self._dispatchers.setdefault(name, {})[id(dispatcher)] = dispatcher
        self._stack.append([name, now, 0.0])

    def on_end(self, ev):
        name, began, nested = self._stack.pop()
        seconds = time.perf_counter() - began
        record = self._functions[name]
        record["self_s"] += seconds - nested
        recursive = any(entry[0] == name for entry in self._stack)
        if not recursive:  # a recursive compile's seconds are in its outer one's
            record["inclusive_s"] += seconds
        if self._stack:
            self._stack[-1][2] += seconds
        # Event.is_failed is inverted in numba 0.68 (True when there is no exception).
        if getattr(ev, "_exc_details", None) is None:
            record["signatures"].append(
                {
                    "args": [str(a) for a in ev.data["args"]],
                    "self_s": seconds - nested,
                    "inclusive_s": 0.0 if recursive else seconds,
                    "from_python": not self._stack,
                    "used_by": [],
                    "used": None,
                }
            )
        else:
            record["failed"] += 1

    def mark_used(self) -> None:
        """Mark each compiled signature of hcid with the call sites whose final typing calls it.

        numba types a function in passes; a call typed on an early pass with
        argument types the final pass no longer has (``Literal[int](0)`` for a
        variable that starts at 0 and changes in a loop) still compiles its
        callee. ``used`` is whether a signature is reachable from one compiled
        for a call from Python through final typings; numba's own functions
        (called through templates, not dispatchers) are left at None.
        """
        from numba.core import ir, types

        sites = {}  # (callee, args) -> [((caller, args), "caller:line")]
        for name, dispatchers in self._dispatchers.items():
            for dispatcher in dispatchers.values():
                for sig, cres in dispatcher.overloads.items():
                    annotation = getattr(cres, "type_annotation", None)
                    if annotation is None:  # loaded from the cache
                        continue
                    caller = (name, tuple(str(a) for a in sig))
                    for expr, calltype in annotation.calltypes.items():
                        if not (isinstance(expr, ir.Expr) and expr.op == "call" and calltype is not None):
                            continue
                        callee = annotation.typemap.get(expr.func.name)
                        if isinstance(callee, types.Dispatcher):
                            key = (_name(callee.dispatcher.py_func), tuple(str(a) for a in calltype.args))
                            site = f"{name.rsplit('.', 1)[-1]}:{expr.loc.line}"
                            sites.setdefault(key, []).append((caller, site))
        ours = [
            (name, sig)
            for name, record in self._functions.items()
            if record["module"].startswith("hcid")
            for sig in record["signatures"]
        ]
        used = {(name, tuple(sig["args"])) for name, sig in ours if sig["from_python"]}
        grown = True
        while grown:
            grown = False
            for name, sig in ours:
                key = (name, tuple(sig["args"]))
                if key not in used and any(caller in used for caller, _ in sites.get(key, ())):
                    used.add(key)
                    grown = True
        for name, sig in ours:
            key = (name, tuple(sig["args"]))
            sig["used"] = key in used
            sig["used_by"] = sorted({site for _, site in sites.get(key, ())})

    def _caller(self) -> str:
        """The innermost hcid function on the Python stack (the call that needed the compile)."""
        frame = sys._getframe(2)
        while frame is not None:
            if frame.f_code.co_filename.startswith(self._package):
                return f"{frame.f_globals.get('__name__', '?')}.{frame.f_code.co_qualname}"
            frame = frame.f_back
        return "?"

    @staticmethod
    def _importing() -> bool:
        frame = sys._getframe(2)
        while frame is not None:
            if frame.f_code.co_filename.startswith("<frozen importlib._bootstrap"):
                return True
            frame = frame.f_back
        return False

    def functions(self) -> list[dict]:
        return list(self._functions.values())


# --------------------------------------------------------------------------- the parent


def _environment(cache: Path) -> dict:
    env = dict(os.environ)
    env["NUMBA_CACHE_DIR"] = str(cache)
    env["PYTHONPATH"] = os.pathsep.join([str(SOURCE), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _hcid_args(config: Path, run: Path, jobs: int) -> list[str]:
    return ["run", str(config), "--run", str(run), "--jobs", str(jobs), "--quiet"]


def _check(proc: subprocess.CompletedProcess, what: str) -> None:
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout + proc.stderr)
        sys.exit(f"cold_start: {what} failed with exit code {proc.returncode}")


def _run(command: list[str], cache: Path, what: str, env: dict | None = None) -> tuple[float, float]:
    """Wall and CPU seconds of a command run with NUMBA_CACHE_DIR=cache (and ``env`` set).

    The CPU seconds are those of the process and of every worker it waited for.
    """
    cpu = _children_cpu()
    start = time.perf_counter()
    environment = _environment(cache) | (env or {})
    proc = subprocess.run(command, cwd=SOURCE, env=environment, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    _check(proc, what)
    return seconds, _children_cpu() - cpu


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _recorded(config: Path, cache: Path, run: Path, out: Path) -> dict:
    """A recorded ``hcid run --jobs 1`` in a child process; what the child saw, and its wall seconds."""
    command = [sys.executable, __file__, CHILD, str(out), *_hcid_args(config, run, 1)]
    seconds, cpu = _run(command, cache, "the recorded run")
    result = json.loads(out.read_text())
    if Path(result["numba_cache_dir"]).resolve() != cache.resolve():
        sys.exit(f"cold_start: the child's numba cache is {result['numba_cache_dir']}, not {cache}")
    result["process_s"] = seconds
    result["cpu_s"] = cpu
    result["cache_index_files"] = _index_files(cache)
    return result


def _warm_up(cache: Path) -> tuple[float, float]:
    """Wall and CPU seconds of the install step's warm-up (:data:`WARM_UP`) into ``cache``.

    An hcid from before ``compile_before_fork`` had no warm-up: there it does nothing.
    """
    command = [sys.executable, "-c", f"try:\n    exec({WARM_UP!r})\nexcept ImportError:\n    pass"]
    return _run(command, cache, "the install's warm-up", {"OPENBLAS_NUM_THREADS": "1"})


def _timed(config: Path, cache: Path, run: Path, jobs: int) -> tuple[float, float]:
    """Wall and CPU seconds of the plain ``hcid run`` command (``python -m hcid``)."""
    command = [sys.executable, "-m", "hcid", *_hcid_args(config, run, jobs)]
    return _run(command, cache, f"hcid run --jobs {jobs}")


def _shorten(name: str, width: int) -> str:
    return name if len(name) <= width else "..." + name[len(name) - width + 3 :]


def _differing(signatures: list[dict]) -> list[int]:
    """The argument positions where the signatures differ."""
    args = [sig["args"] for sig in signatures]
    if len({len(a) for a in args}) > 1:
        return list(range(max(len(a) for a in args)))
    return [i for i, types in enumerate(zip(*args, strict=True)) if len(set(types)) > 1]


def _unused(f: dict) -> list[dict]:
    return [sig for sig in f["signatures"] if sig["used"] is False]


def _index_files(cache: Path) -> int:
    return sum(1 for _ in cache.rglob("*.nbi"))


def _group(module: str) -> str:
    return module if module in GROUPS else OTHER


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def _commit() -> str:
    def git(*args):
        proc = subprocess.run(["git", *args], cwd=SOURCE, capture_output=True, text=True)
        return proc.stdout.strip() if proc.returncode == 0 else ""

    head = git("rev-parse", "--short", "HEAD") or "unknown"
    return head + (" + uncommitted changes under hcid/" if git("status", "--porcelain", "--", "hcid") else "")


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _print_compiles(cold: dict, warm: dict) -> None:
    functions = cold["functions"]
    total = sum(f["self_s"] for f in functions)
    n_sigs = sum(len(f["signatures"]) for f in functions)
    print(
        f"cold --jobs 1, recorded: {total:.1f} s compiling of {cold['process_s']:.1f} s wall "
        f"({cold['cpu_s']:.1f} s cpu); "
        f"{len(functions)} functions, {n_sigs} signatures; {cold['cache_index_files']} cache index files"
    )
    print()
    header = f"{'functions':>9} {'signatures':>10} {'unused':>6} {'self s':>8} {'share':>6} {'unused s':>8}"
    print(f"{'kernel group':<24} {header}")
    groups = {g: [] for g in (*GROUPS, OTHER)}
    for f in functions:
        groups[_group(f["module"])].append(f)
    for name, members in groups.items():
        seconds = sum(f["self_s"] for f in members)
        sigs = sum(len(f["signatures"]) for f in members)
        unused = [sig for f in members for sig in _unused(f)]
        share = seconds / total if total else 0.0
        print(
            f"{name:<24} {len(members):>9} {sigs:>10} {len(unused):>6} {seconds:>8.2f} {share:>6.1%} "
            f"{sum(sig['self_s'] for sig in unused):>8.2f}"
        )
    unused = [sig for f in functions for sig in _unused(f)]
    print(
        f"{'total':<24} {len(functions):>9} {n_sigs:>10} {len(unused):>6} {total:>8.2f} {'':>6} "
        f"{sum(sig['self_s'] for sig in unused):>8.2f}"
    )
    print()
    width = min(max(len(f"{f['module']}.{f['qualname']}") for f in functions), 60)
    header = f"{'sigs':>4} {'unused':>6} {'self s':>7} {'incl s':>7} {'at s':>6}  first compiled from"
    print(f"{'function (by self seconds)':<{width}} {header}")
    ranked = sorted(functions, key=lambda f: f["self_s"], reverse=True)
    for f in ranked[:TOP_FUNCTIONS]:
        name = f"{f['module']}.{f['qualname']}"
        sigs = f"{len(f['signatures'])}" + (f"+{f['failed']}x" if f["failed"] else "")
        unused = len(_unused(f)) if f["module"].startswith("hcid") else "-"
        print(
            f"{_shorten(name, width):<{width}} {sigs:>4} {unused:>6} {f['self_s']:>7.2f} "
            f"{f['inclusive_s']:>7.2f} {f['first_at_s']:>6.1f}  {f['first_from']}"
        )
    if len(ranked) > TOP_FUNCTIONS:
        rest = ranked[TOP_FUNCTIONS:]
        print(f"... {len(rest)} more, {sum(f['self_s'] for f in rest):.2f} s self in all")
    print()
    warm_sigs = sum(len(f["signatures"]) for f in warm["functions"])
    hits = sum(d["cache_hits"] for d in warm["dispatchers"].values())
    loaded = sum(1 for d in warm["dispatchers"].values() if d["cache_hits"])
    print(
        f"warm --jobs 1, recorded: {warm['process_s']:.1f} s wall ({warm['cpu_s']:.1f} s cpu); "
        f"{loaded} hcid functions loaded from the cache ({hits} signatures); "
        f"{len(warm['functions'])} functions compiled ({warm_sigs} signatures)"
    )


def _notes(cold: dict, warm: dict) -> list[str]:
    notes = []
    functions = cold["functions"]
    at_import = [f for f in functions if f["at_import"]]
    notes.append(
        f"compiled while a module was imported: {len(at_import)} functions"
        + (": " + ", ".join(f"{f['module']}.{f['qualname']}" for f in at_import) if at_import else "")
        + f"; at a first call: {sum(1 for f in functions if f['at_call'])}"
    )
    unused = [sig for f in functions for sig in _unused(f)]
    if unused:
        seconds = sum(sig["self_s"] for sig in unused)
        total = sum(f["self_s"] for f in functions)
        notes.append(
            f"{len(unused)} signatures of hcid compiled that no final typing calls (an early typing pass's "
            f"argument types): {seconds:.1f} s self, {seconds / total:.0%} of the compile time"
        )
    for f in functions:
        name = f"{f['module']}.{f['qualname']}"
        if f["parallel"] or "parallel" in f["qualname"] or "threads" in f["qualname"]:
            notes.append(f"{name}: a parallel variant compiled ({len(f['signatures'])} signatures)")
        if f["module"].startswith("hcid") and len(f["signatures"]) > 1:
            positions = _differing(f["signatures"])
            lines = [f"{name}: {len(f['signatures'])} signatures, differing in arguments {positions}:"]
            for sig in f["signatures"]:
                types = ", ".join(sig["args"][i] if i < len(sig["args"]) else "-" for i in positions)
                called = ", ".join(sig["used_by"]) or ("Python" if sig["from_python"] else "nothing")
                mark = "used" if sig["used"] else "UNUSED"
                lines.append(f"    ({types})  {sig['self_s']:.2f} s self  {mark}, called from {called}")
            notes.append("\n".join(lines))
        if f["failed"]:
            notes.append(f"{name}: {f['failed']} compiles failed (overload resolution tried it)")
    for f in warm["functions"]:
        sigs = "; ".join(f"({', '.join(sig['args'])})" for sig in f["signatures"])
        notes.append(f"warm run compiled {f['module']}.{f['qualname']} (a cache miss): {sigs}")
    return notes


def _print_installed(installed: dict, cold: dict) -> None:
    """What the first run after the install's warm-up still compiles."""
    functions = installed["functions"]
    seconds = sum(f["self_s"] for f in functions)
    n_sigs = sum(len(f["signatures"]) for f in functions)
    print(
        f"install's warm-up on a fresh cache: {installed['warm_up_s']:.1f} s wall "
        f"({installed['warm_up_cpu_s']:.1f} s cpu), {installed['warm_up_index_files']} cache index files "
        f"(cold --jobs 1 recorded: {cold['cache_index_files']})"
    )
    print(
        f"first run after it, --jobs 1, recorded: {installed['process_s']:.1f} s wall "
        f"({installed['cpu_s']:.1f} s cpu); {len(functions)} functions compiled ({n_sigs} signatures), "
        f"{seconds:.2f} s self"
    )
    for f in sorted(functions, key=lambda f: f["self_s"], reverse=True):
        if f["module"].startswith("hcid"):
            name = f"{f['module']}.{f['qualname']}"
            print(f"    {name}: {len(f['signatures'])} signatures, {f['self_s']:.2f} s self")
    others = [f for f in functions if not f["module"].startswith("hcid")]
    if others:
        print(f"    and {len(others)} of numba's own, {sum(f['self_s'] for f in others):.2f} s self")


def _print_walls(repeat, kinds, walls, cpus, warm_ups, warm, cold, j2_index_files):
    """The alternated rounds' wall (and CPU) seconds side by side."""
    print(f"{'seconds, wall / cpu':<20}" + "".join(f"{kind:>20}" for kind in kinds))
    for i in range(repeat):
        cells = "".join(f"{walls[k][i]:>12.1f} / {cpus[k][i]:>5.1f}" for k in kinds)
        print(f"{f'round {i + 1}':<20}{cells}")
    if repeat > 1:
        for label, pick in (("best wall", min), ("median wall", statistics.median)):
            print(f"{label:<20}" + "".join(f"{pick(walls[k]):>12.1f}{'':>8}" for k in kinds))
    cold2, warm2, cold1, installed = (min(walls[k]) for k in kinds)

    def per_round(kind):
        return ", ".join(f"{x / w:.2f}" for x, w in zip(walls[kind], walls["warm --jobs 2"], strict=True))

    print(
        f"cold start over warm, --jobs 2: {cold2 - warm2:.1f} s ({cold2 / warm2:.1f} x, best walls; "
        f"per round {per_round('cold --jobs 2')} x); --jobs 1: {cold1 - warm['process_s']:.1f} s "
        f"(warm: the recorded run)"
    )
    walls_s, cpus_s = (", ".join(f"{x:.1f}" for x in values) for values in zip(*warm_ups, strict=True))
    print(
        f"first run after the install's warm-up over warm, --jobs 2: {installed - warm2:.1f} s "
        f"({installed / warm2:.2f} x, best walls; per round {per_round('installed --jobs 2')} x); "
        f"the warm-up itself (not in them): {walls_s} s wall, {cpus_s} s cpu"
    )
    if any(n != cold["cache_index_files"] for n in j2_index_files):
        print(
            f"cache index files after cold --jobs 2: {j2_index_files} "
            f"(--jobs 1 recorded: {cold['cache_index_files']})"
        )
    print()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="configs/ci.yaml", help="study config (default: configs/ci.yaml)")
    parser.add_argument("--json", type=Path, help="also write the results here as JSON")
    parser.add_argument(
        "--repeat", type=int, default=1, help="wall-time rounds (default 1; 0: only the recorded runs)"
    )
    parser.add_argument(
        "--source", type=Path, default=ROOT, help="the hcid checkout to measure (default: this one)"
    )
    parser.add_argument(
        "--smoke",
        action="store_true",
        help="one round, every run after the first on a copy of its cache: every path in about 30 s",
    )
    args = parser.parse_args()
    global SOURCE
    SOURCE = args.source.resolve()
    if not (SOURCE / "hcid" / "__init__.py").is_file():
        parser.error(f"--source: no hcid package in {args.source}")
    if args.repeat < 0:
        parser.error(f"--repeat: must be at least 0, got {args.repeat}")
    repeat = 1 if args.smoke else args.repeat
    config = Path(args.config).resolve()
    if not config.is_file():
        parser.error(f"--config: no such file: {args.config}")
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        parser.error("NUMBA_DISABLE_JIT is set: nothing would compile")

    began = time.perf_counter()
    load_before = os.getloadavg()
    commit = _commit()
    print(f"cold start of hcid run {args.config} (commit {commit})")
    print(f"cpu {_cpu()}, {os.cpu_count()} cores; load before {_load()}")
    if args.smoke:
        print(
            "smoke run: every run after the first recorded one starts from a copy of its cache, so the "
            "later cold and installed figures are warm ones, not worth keeping"
        )
    print()

    kinds = ("cold --jobs 2", "warm --jobs 2", "cold --jobs 1", "installed --jobs 2")
    walls = {kind: [] for kind in kinds}
    cpus = {kind: [] for kind in kinds}
    warm_ups = []
    j2_index_files = []
    with tempfile.TemporaryDirectory(prefix="hcid-cold-start-") as tmp:
        tmp = Path(tmp)
        recorded = tmp / "cache-recorded"

        def fresh(name: str) -> Path:
            """A cache folder for a cold run: empty, or in a smoke run a copy of the recorded one."""
            if args.smoke:
                shutil.copytree(recorded, tmp / name)
            return tmp / name

        cold = _recorded(config, recorded, tmp / "run-cold", tmp / "cold.json")
        warm = _recorded(config, recorded, tmp / "run-warm", tmp / "warm.json")
        cache = fresh("cache-installed")
        warm_up_s, warm_up_cpu_s = _warm_up(cache)
        warm_up_index_files = _index_files(cache)
        installed = _recorded(config, cache, tmp / "run-installed", tmp / "installed.json")
        installed.update(
            warm_up_s=warm_up_s, warm_up_cpu_s=warm_up_cpu_s, warm_up_index_files=warm_up_index_files
        )
        _print_compiles(cold, warm)
        print()
        _print_installed(installed, cold)
        print()
        # Alternating, so that load from other work on the machine hits every kind of run alike.
        for i in range(repeat):
            cache = fresh(f"cache-{i}-jobs2")
            installed_cache = fresh(f"cache-{i}-installed")
            runs = (
                ("cold --jobs 2", cache, 2),
                ("warm --jobs 2", cache, 2),
                ("cold --jobs 1", fresh(f"cache-{i}-jobs1"), 1),
                ("installed --jobs 2", installed_cache, 2),
            )
            for kind, folder, jobs in runs:
                if kind.startswith("installed"):
                    warm_ups.append(_warm_up(folder))
                wall, cpu = _timed(config, folder, tmp / f"run-{i}-{kind.replace(' ', '')}", jobs)
                walls[kind].append(wall)
                cpus[kind].append(cpu)
                if kind == "cold --jobs 2":
                    j2_index_files.append(_index_files(cache))
    load_after = os.getloadavg()

    if repeat:
        _print_walls(repeat, kinds, walls, cpus, warm_ups, warm, cold, j2_index_files)
    for note in _notes(cold, warm):
        print(f"note: {note}")
    seconds = time.perf_counter() - began
    print(f"load after {_load()}; benchmark took {seconds:.0f} s")

    if args.json is not None:
        result = {
            "commit": commit,
            "config": args.config,
            "smoke": args.smoke,
            "cpu": _cpu(),
            "cores": os.cpu_count(),
            "load_before": load_before,
            "load_after": load_after,
            "numba": cold["numba"],
            "recorded_cold": cold,
            "recorded_warm": warm,
            "recorded_installed": installed,
            "wall_s": walls,
            "cpu_s": cpus,
            "warm_up_s": warm_ups,
            "cold_jobs2_cache_index_files": j2_index_files,
            "benchmark_s": seconds,
        }
        args.json.write_text(json.dumps(result, indent=1))
        print(f"results: {args.json}")


if __name__ == "__main__":
    if sys.argv[1:2] == [CHILD]:
        _child(sys.argv[2], sys.argv[3:])
    else:
        main()

"""An export built for a flight computer: the targets, their flags, and what a build costs.

=============  =====================  ==========================================================
target         compiler               flags (beside the checking flags)
=============  =====================  ==========================================================
``host``       the system's ``cc``    none
``cortex-m4``  ``arm-none-eabi-gcc``  ``-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16
                                      -mfloat-abi=hard``: a single-precision FPU (double runs
                                      in software, ``__aeabi_d*`` calls)
``cortex-m7``  ``arm-none-eabi-gcc``  ``-mcpu=cortex-m7 -mthumb -mfpu=fpv5-d16
                                      -mfloat-abi=hard``: single and double in hardware
=============  =====================  ==========================================================

Embedded targets add :data:`FREESTANDING_FLAGS` (``-ffreestanding``, one section per function
and object, ``-fstack-usage`` and ``-fcallgraph-info=su``). The compilers are Debian's
``gcc-arm-none-eabi`` with ``libnewlib-arm-none-eabi`` (newlib's ``math.h``; the law calls
``sqrt``/``fabs``/``fmin``/``fmax`` and ``memcpy``/``memset`` and nothing else).

:func:`build_for_target` compiles an export's law to an object at exactly these flags (the
Makefile's ``cortex-m4`` and ``cortex-m7`` rules use the same, :data:`TARGETS`) and measures
it (:class:`TargetBuild`): code, constants and static data by section (``size -A``), the
caller's struct (the struct compiled alone, its size read by ``nm -S``), the deepest stack of
a step (GCC's call graph with each function's frame: the sum along the heaviest path from
``flexctl_ctrl_step``; library functions not counted), the symbols the law needs from the C
library, and whether it allocates, recurses or sizes a frame at run time (refused).
"""

from __future__ import annotations

import re
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from flexctl.model.errors import InputTypeError, InputValueError

__all__ = ["Target", "TARGETS", "FREESTANDING_FLAGS", "TargetBuild", "check_target",
           "find_target_compiler", "build_for_target", "target_flags", "run_tool"]

#: Debian's packages of the cross tools (named in the message when they are missing).
CROSS_PACKAGES = "gcc-arm-none-eabi libnewlib-arm-none-eabi"


@dataclass(frozen=True)
class Target:
    """A processor an export is built for.

    Attributes
    ----------
    name : str
        ``"host"``, ``"cortex-m4"``, ``"cortex-m7"``.
    compiler : str or None
        The C compiler's name (None: the host's, :func:`~controllers.codegen.find_compiler`).
    flags : tuple of str
        The processor's flags (CPU, instruction set, FPU, float ABI).
    tools : str
        Prefix of the binutils (``"arm-none-eabi-"``; ``""`` on the host).
    double_in_hardware : bool
        The FPU computes in double precision.
    board : str or None
        The QEMU machine that emulates it (an MPS2 board), for the processor in the loop.
    """

    name: str
    compiler: str | None
    flags: tuple
    tools: str
    double_in_hardware: bool
    board: str | None = None

    @property
    def embedded(self) -> bool:
        """Built freestanding for a microcontroller."""
        return self.compiler is not None


#: The targets, by name.
TARGETS = {
    "host": Target("host", None, (), "", True),
    "cortex-m4": Target("cortex-m4", "arm-none-eabi-gcc",
                        ("-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"),
                        "arm-none-eabi-", False, "mps2-an386"),
    "cortex-m7": Target("cortex-m7", "arm-none-eabi-gcc",
                        ("-mcpu=cortex-m7", "-mthumb", "-mfpu=fpv5-d16", "-mfloat-abi=hard"),
                        "arm-none-eabi-", True, "mps2-an500"),
}
#: Flags of every embedded build: no hosted library assumed, sections per function (the
#: linker keeps what is called), and the stack use of each function and the call graph.
FREESTANDING_FLAGS = ("-ffreestanding", "-ffunction-sections", "-fdata-sections",
                      "-fstack-usage", "-fcallgraph-info=su")
_ALLOCATORS = ("malloc", "calloc", "realloc", "free", "alloca", "__builtin_alloca")


def check_target(name) -> Target:
    """The :class:`Target` named ``name``, or a clear error.

    Parameters
    ----------
    name : str
        One of :data:`TARGETS`.

    Raises
    ------
    InputTypeError
        If ``name`` is not a string.
    InputValueError
        If it names no target.
    """
    if not isinstance(name, str):
        raise InputTypeError(f"export target must be a string, one of {tuple(TARGETS)}; got "
                             f"{type(name).__name__}")
    if name not in TARGETS:
        raise InputValueError(f"export target must be one of {tuple(TARGETS)}; got {name!r}")
    return TARGETS[name]


def target_flags(target: Target, precision: str) -> tuple:
    """Every flag a law is compiled with for ``target`` in ``precision``: the checking flags,
    the precision's, the processor's and, embedded, :data:`FREESTANDING_FLAGS`.

    Parameters
    ----------
    target : Target
        The processor.
    precision : {"double", "float"}
        The export's real type.
    """
    from .compiler import C_FLAGS
    from .precision import PRECISION_FLAGS

    return (*C_FLAGS, *PRECISION_FLAGS[precision], *target.flags,
            *(FREESTANDING_FLAGS if target.embedded else ()))


def find_target_compiler(target: Target, cc: str | None = None) -> str:
    """The path of ``target``'s C compiler.

    Parameters
    ----------
    target : Target
        The processor.
    cc : str, optional
        A compiler's name or path used instead. Default: the target's.

    Raises
    ------
    controllers.codegen.CompileError
        If it is not installed (naming the Debian packages that provide it).
    """
    from .compiler import CompileError, find_compiler

    if not target.embedded:
        return find_compiler(cc)
    name = cc or target.compiler
    path = shutil.which(name)
    if path is None:
        raise CompileError(f"{name} not found: building for {target.name} needs Debian's "
                           f"{CROSS_PACKAGES}")
    return path


@dataclass(frozen=True)
class TargetBuild:
    """What an export's law costs on a target (module docstring); bytes unless stated.

    Attributes
    ----------
    target, precision : str
    flags : tuple of str
        The compilation's flags.
    code_bytes : int
        Machine code (``.text`` sections).
    constant_bytes : int
        Read-only data: the law's matrices, tables, sparsity patterns (``.rodata``).
    static_ram_bytes : int
        Writable static data (``.data`` and ``.bss``): zero for an export.
    struct_bytes : int
        The caller's struct on this target (``flexctl_ctrl_size()``): the law's memory
        and work arrays.
    stack_bytes : int or None
        Deepest stack of one step: frames along the heaviest call path from
        ``flexctl_ctrl_step`` (library functions not counted); None on the host.
    stack_path : tuple of str
        That path's functions.
    library_calls : tuple of str
        Functions the law needs from the C library (and, for double on a single-precision
        FPU, the compiler's software double arithmetic, ``__aeabi_d*``).
    software_double : bool
        Double arithmetic runs in software (``__aeabi_d*`` calls other than the conversions
        between double and 64-bit integers, which the Cortex-M floating-point units do not
        make).
    """

    target: str
    precision: str
    flags: tuple
    code_bytes: int
    constant_bytes: int
    static_ram_bytes: int
    struct_bytes: int
    stack_bytes: int | None
    stack_path: tuple
    library_calls: tuple
    software_double: bool

    def as_dict(self) -> dict:
        """Plain dictionary (JSON-ready)."""
        out = asdict(self)
        out["flags"], out["stack_path"] = list(self.flags), list(self.stack_path)
        out["library_calls"] = list(self.library_calls)
        return out


def _tool(target: Target, name: str) -> str:
    from .compiler import CompileError

    path = shutil.which(target.tools + name)
    if path is None:
        raise CompileError(f"{target.tools + name} not found (binutils of {target.name})")
    return path


def run_tool(command, cwd) -> str:
    """Run a compiler or binutil; its standard output, or a ``CompileError`` with its
    messages.

    Parameters
    ----------
    command : list
        The command line (``command[0]`` the tool's path), entries made strings.
    cwd : str or pathlib.Path
        Folder it runs in.
    """
    from .compiler import run_compiler

    command = [str(c) for c in command]
    return run_compiler(Path(command[0]).name, command, " ".join(command[1:]), cwd)


def build_for_target(export, target="cortex-m4", cc: str | None = None) -> TargetBuild:
    """Compile ``export``'s law for ``target`` and measure it (module docstring).

    Parameters
    ----------
    export : CExport
        The written export (:func:`~controllers.codegen.export_c`); its folder is only read.
    target : str or Target, optional
        One of :data:`TARGETS`. Default ``"cortex-m4"``.
    cc : str, optional
        The compiler, instead of the target's.

    Raises
    ------
    controllers.codegen.CompileError
        If the compiler or its binutils are missing, or the compiler fails.
    controllers.codegen.ExportRefused
        If the law allocates memory, recurses or sizes a stack frame at run time.
    """
    target = target if isinstance(target, Target) else check_target(target)
    compiler = find_target_compiler(target, cc)
    flags = target_flags(target, export.precision)
    with tempfile.TemporaryDirectory(prefix="flexctl-target-") as build:
        obj = Path(build, "law.o")
        run_tool([compiler, *flags, "-c", Path(export.source).resolve(), "-o", obj], build)
        sections = _sections(run_tool([_tool(target, "size"), "-A", obj], build))
        external = tuple(sorted(line.split()[-1] for line in run_tool(
            [_tool(target, "nm"), "-u", obj], build).splitlines() if line.strip()))
        stack, path = _deepest_stack(Path(build, "law.ci")) if target.embedded else (None, ())
        struct = _struct_bytes(export, target, compiler, flags, build)
    _refuse_unsafe(external)
    return TargetBuild(
        target=target.name, precision=export.precision, flags=tuple(flags),
        code_bytes=sections["text"], constant_bytes=sections["rodata"],
        static_ram_bytes=sections["data"] + sections["bss"], struct_bytes=struct,
        stack_bytes=stack, stack_path=path, library_calls=external,
        software_double=any(name.startswith("__aeabi_d") and name not in _WIDE_CONVERSIONS
                            for name in external))


#: The run-time helpers that convert between double and 64-bit integers (CasADi's index type,
#: in its table look-ups): no floating-point unit converts those, so they appear with
#: hardware double too; they are not double arithmetic in software.
_WIDE_CONVERSIONS = ("__aeabi_d2lz", "__aeabi_d2ulz", "__aeabi_l2d", "__aeabi_ul2d")


def _sections(table: str) -> dict:
    """Bytes of ``.text``, ``.rodata``, ``.data``, ``.bss`` (each with its per-function
    sections) in ``size -A``'s table."""
    out = dict.fromkeys(("text", "rodata", "data", "bss"), 0)
    for line in table.splitlines():
        parts = line.split()
        if len(parts) < 2 or not parts[1].isdigit():
            continue
        kind = parts[0].lstrip(".").split(".")[0]
        if parts[0].startswith(".data.rel.ro"):
            kind = "rodata"             # the host's read-only data with relocations
        if kind in out:
            out[kind] += int(parts[1])
    return out


def _struct_bytes(export, target, compiler, flags, build) -> int:
    """``sizeof(struct flexctl_ctrl)`` on ``target``: the struct's definition compiled alone
    into an object holding one array of that size, read by ``nm -S``."""
    source = export.source.read_text(encoding="utf-8")
    defines = "\n".join(re.findall(r"^#define FLEXCTL_(?:SZ_\w+|MAGIC) .*$", source, re.M))
    struct = re.search(r"^struct flexctl_ctrl \{.*?^\};", source, re.M | re.S).group(0)
    probe = Path(build, "probe.c")
    probe.write_text(f'#include "{export.header.name}"\n{defines}\n{struct}\n'
                     "const char flexctl_struct_probe[sizeof(struct flexctl_ctrl)] = {0};\n",
                     encoding="utf-8")
    obj = Path(build, "probe.o")
    run_tool([compiler, *[f for f in flags if not f.startswith(("-fstack", "-fcallgraph"))],
          f"-I{Path(export.directory).resolve()}", "-c", probe, "-o", obj], build)
    for line in run_tool([_tool(target, "nm"), "-S", obj], build).splitlines():
        if line.endswith("flexctl_struct_probe"):
            return int(line.split()[1], 16)
    raise RuntimeError("the struct's probe has no symbol")       # nm always lists it


def _deepest_stack(graph_file: Path) -> tuple:
    """``(bytes, path)``: the heaviest chain of frames from ``flexctl_ctrl_step`` in GCC's
    call graph (``-fcallgraph-info=su``)."""
    from .program import ExportRefused

    text = graph_file.read_text(encoding="utf-8")
    frames, calls = {}, {}
    for title, label in re.findall(r'node: \{ title: "([^"]+)" label: "([^"]+)"', text):
        found = re.search(r"(\d+) bytes \((\w+)\)", label)
        if found and found.group(2) not in ("static", "bounded"):
            raise ExportRefused(f"export: {label.split(chr(92))[0]} sizes its stack frame at "
                                f"run time ({found.group(2)}); an export must not")
        frames[title] = int(found.group(1)) if found else 0
    for source, target in re.findall(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"',
                                     text):
        calls.setdefault(source, []).append(target)
    root = next(t for t in frames if t.rsplit(":", 1)[-1] == "flexctl_ctrl_step")
    best: dict = {}

    def heaviest(node, chain):
        if node in chain:
            raise ExportRefused(f"export: the law recurses ({' -> '.join(chain)} -> {node}); "
                                "an export must not")
        if node not in best:
            below = [heaviest(child, chain + (node,)) for child in calls.get(node, ())]
            weight, path = max(below, default=(0, ()))
            best[node] = (frames.get(node, 0) + weight, (node,) + path)
        return best[node]

    total, path = heaviest(root, ())
    return total, tuple(name.rsplit(":", 1)[-1] for name in path)


def _refuse_unsafe(external) -> None:
    from .program import ExportRefused

    allocating = sorted(set(external) & set(_ALLOCATORS))
    if allocating:
        raise ExportRefused(f"export: the law calls {', '.join(allocating)}; an export must "
                            "not allocate memory")

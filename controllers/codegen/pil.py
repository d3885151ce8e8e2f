"""Processor in the loop: an export's step cross-compiled and run under QEMU on an MPS2 board.

:func:`run_on_target` links the law (built at :func:`~controllers.codegen.targets.target_flags`)
with a small freestanding program: a vector table and reset handler that enable the FPU, the
recorded times and inputs as constant arrays, and a loop that calls ``flexctl_ctrl_step`` on
each and writes the command's bits, the return code and the step's count of the CMSDK timer
to the host through semihosting. QEMU runs it on the board of the target (``mps2-an386`` for
the Cortex-M4, ``mps2-an500`` for the Cortex-M7) with ``-icount shift=`` :data:`ICOUNT_SHIFT`:
virtual time advances ``2**shift`` ns per instruction executed, so the timer counts
instructions, deterministically. Before the steps the program times a loop of known length
(:data:`CALIBRATION_LOOPS` iterations of two instructions) and two reads of the timer back to
back: the instructions of a step are its ticks less the reads', times the loop's instructions
per tick.

This counts instructions, not cycles: QEMU models no pipeline, cache, flash wait state or
bus, and a Cortex-M's divisions, loads and branches take more than one cycle. The time
:attr:`PILRun.time_estimate_s` divides the count by a stated clock (:data:`CLOCKS`), one
instruction a cycle: an estimate, not a timing.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["run_on_target", "PILRun", "EmulationError", "find_emulator", "ICOUNT_SHIFT",
           "CALIBRATION_LOOPS", "CLOCKS"]

#: ``-icount shift``: 64 ns of virtual time per instruction, 1.6 ticks of the boards' 25 MHz
#: timer: the count resolves single instructions.
ICOUNT_SHIFT = 6
#: Iterations of the two-instruction loop that calibrates ticks per instruction.
CALIBRATION_LOOPS = 10000
#: Clocks (Hz) the instruction counts are turned into times at: a typical Cortex-M4F (STM32F4)
#: and Cortex-M7 (STM32H7, as issue 48 states 400 MHz).
CLOCKS = {"cortex-m4": 168e6, "cortex-m7": 400e6}
#: Longest a QEMU run may take, s (wall time).
TIMEOUT_S = 300.0
EMULATOR = "qemu-system-arm"


class EmulationError(RuntimeError):
    """QEMU is missing, or the program under it failed or printed what was not expected."""


def find_emulator() -> str:
    """The path of ``qemu-system-arm``.

    Raises
    ------
    EmulationError
        If it is not installed (naming Debian's package).
    """
    path = shutil.which(EMULATOR)
    if path is None:
        raise EmulationError(f"{EMULATOR} not found: the processor in the loop needs Debian's "
                             "qemu-system-arm")
    return path


@dataclass(frozen=True, eq=False)
class PILRun:
    """A run of the step on the emulated target; made by :func:`run_on_target`.

    Attributes
    ----------
    target, board, precision : str
    commands : ndarray, shape (K,)
        The step's command at each sample, in the law's output unit.
    codes : ndarray of int, shape (K,)
        Its return codes.
    instructions : ndarray of int, shape (K,)
        Instructions each step executed (QEMU's count under ``-icount``; not cycles).
    ticks_per_instruction : float
        The calibration: timer ticks per instruction.
    clock_hz : float
        The clock of :attr:`time_estimate_s`.
    """

    target: str
    board: str
    precision: str
    commands: np.ndarray
    codes: np.ndarray
    instructions: np.ndarray
    ticks_per_instruction: float
    clock_hz: float

    @property
    def time_estimate_s(self) -> np.ndarray:
        """Instructions over :attr:`clock_hz`: seconds per step at one instruction a cycle
        (an estimate, not a timing: module docstring)."""
        return self.instructions / self.clock_hz

    def summary(self) -> dict:
        """Instruction counts per step (median, largest) and their time estimates."""
        return {"target": self.target, "board": self.board, "precision": self.precision,
                "steps": int(self.codes.size),
                "instructions_median": float(np.median(self.instructions)),
                "instructions_max": int(self.instructions.max()),
                "clock_hz": self.clock_hz,
                "time_estimate_median_s": float(np.median(self.time_estimate_s)),
                "time_estimate_max_s": float(self.time_estimate_s.max()),
                "note": "instructions counted by QEMU -icount, not cycles: the time assumes "
                        "one instruction a cycle"}


def run_on_target(export, times, inputs, target: str = "cortex-m4",
                  clock_hz: float | None = None) -> PILRun:
    """Run ``export``'s step on ``target`` under QEMU on recorded ``times`` and ``inputs``.

    Parameters
    ----------
    export : CExport
        The written export (:func:`~controllers.codegen.export_c`); its folder is only read.
    times : array_like, shape (K,)
        Sample times, s.
    inputs : array_like, shape (K, n_in)
        The step's input at each time (plant states, or readings of a measurement law).
    target : {"cortex-m4", "cortex-m7"}, optional
        The processor (:data:`~controllers.codegen.targets.TARGETS`). Default
        ``"cortex-m4"``.
    clock_hz : float, optional
        Clock of the time estimate, Hz. Default :data:`CLOCKS` of the target.

    Raises
    ------
    flexctl.model.errors.InputValueError
        If ``target`` is not embedded, or ``inputs`` has not ``n_in`` columns.
    controllers.codegen.CompileError
        If the cross compiler is missing or fails.
    EmulationError
        If QEMU is missing, fails, or the program's output is not complete.
    """
    from flexctl.model.errors import InputValueError

    from .targets import check_target, find_target_compiler, run_tool, target_flags

    chosen = check_target(target)
    if not chosen.embedded:
        raise InputValueError(f"processor in the loop target must be embedded, one of "
                              f"{tuple(CLOCKS)}; got {target!r}")
    times = np.asarray(times, dtype=float).reshape(-1)
    inputs = np.asarray(inputs, dtype=float).reshape(times.size, -1)
    n_in = export.program.n_in
    if inputs.shape[1] != n_in:
        raise InputValueError(f"processor in the loop inputs must have {n_in} columns; got "
                              f"{inputs.shape[1]}")
    compiler, qemu = find_target_compiler(chosen), find_emulator()
    flags = [f for f in target_flags(chosen, export.precision)
             if not f.startswith(("-fstack-usage", "-fcallgraph"))]
    with tempfile.TemporaryDirectory(prefix="flexctl-pil-") as build:
        folder = Path(build)
        (folder / "pil.ld").write_text(_LINKER_SCRIPT, encoding="utf-8")
        (folder / "pil_main.c").write_text(_program(export, times, inputs), encoding="utf-8")
        elf = folder / "pil.elf"
        run_tool([compiler, *flags, f"-I{export.directory}", "pil_main.c", "-nostartfiles",
                  "-T", "pil.ld", "--specs=nano.specs", "--specs=nosys.specs", "-lm", "-o",
                  elf], build)
        output = _emulate(qemu, chosen.board, elf)
    return _parse(output, chosen, export.precision, times.size,
                  clock_hz or CLOCKS[chosen.name])


def _emulate(qemu: str, board: str, elf: Path) -> str:
    command = [qemu, "-M", board, "-nographic",
               "-semihosting-config", "enable=on,target=native",
               "-icount", f"shift={ICOUNT_SHIFT},align=off,sleep=off", "-kernel", str(elf)]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise EmulationError(f"{EMULATOR} -M {board} did not finish in {TIMEOUT_S:g} s") \
            from None
    if done.returncode != 0:
        raise EmulationError(f"{EMULATOR} -M {board} exited with status {done.returncode}: "
                             f"{(done.stderr or done.stdout).strip()[-2000:]}")
    return done.stderr + done.stdout        # QEMU writes semihosting's output to stderr


def _parse(output: str, target, precision: str, steps: int, clock_hz: float) -> PILRun:
    calibration, rows = None, []
    for line in output.splitlines():
        parts = line.split()
        if parts[:1] == ["C"]:
            calibration = [int(p, 16) for p in parts[1:]]
        elif parts[:1] == ["S"]:
            rows.append([int(p, 16) for p in parts[1:]])
    if calibration is None or len(rows) != steps:
        raise EmulationError(f"the program under {EMULATOR} printed {len(rows)} of {steps} "
                             f"steps{'' if calibration else ' and no calibration'}: "
                             f"{output.strip()[-500:]!r}")
    empty, loop = calibration[:2]
    per_instruction = (loop - empty) / (2 * CALIBRATION_LOOPS)
    rows = np.array(rows, dtype=np.uint64)          # k, code, low bits, high bits, ticks
    if precision == "float":
        commands = rows[:, 2].astype(np.uint32).view(np.float32).astype(float)
    else:
        commands = (rows[:, 2] | (rows[:, 3] << np.uint64(32))).view(np.float64)
    instructions = np.rint((rows[:, 4].astype(float) - empty) / per_instruction).astype(int)
    return PILRun(target.name, target.board, precision, commands.copy(),
                  rows[:, 1].astype(int), instructions, float(per_instruction),
                  float(clock_hz))


def _reals(values, precision) -> str:
    suffix = "f" if precision == "float" else ""
    items = [repr(float(v)) + suffix for v in np.asarray(values, dtype=float).reshape(-1)]
    return ",\n  ".join(", ".join(items[i:i + 4]) for i in range(0, len(items), 4))


def _program(export, times, inputs) -> str:
    precision = export.precision
    return _PROGRAM_HEAD + textwrap.dedent(f"""\
        #include "{export.source.name}"

        #define PIL_STEPS {times.size}
        static const flexctl_real pil_times[PIL_STEPS] = {{
          {_reals(times, precision)}
        }};
        static const flexctl_real pil_inputs[PIL_STEPS * FLEXCTL_N_INPUT] = {{
          {_reals(inputs, precision)}
        }};
        static struct flexctl_ctrl pil_ctrl;

        int main(void) {{
          uint32_t start, ticks, bits[2] = {{0u, 0u}};
          int k, code;
          flexctl_real u = 0;
          timer_start();
          pil_calibrate({CALIBRATION_LOOPS}u);
          if (flexctl_ctrl_init(&pil_ctrl) != FLEXCTL_OK) return 1;
          for (k = 0; k < PIL_STEPS; ++k) {{
            start = TIMER_VALUE;
            code = flexctl_ctrl_step(&pil_ctrl, pil_times[k],
                                     &pil_inputs[k * FLEXCTL_N_INPUT], &u);
            ticks = start - TIMER_VALUE;
            memcpy(bits, &u, sizeof u);
            put_row('S', (uint32_t)k, (uint32_t)code, bits[0], bits[1], ticks);
          }}
          return 0;
        }}
        """)


_PROGRAM_HEAD = r"""/* pil_main.c: the exported step on recorded inputs, for QEMU's MPS2 boards. */
#include <stdint.h>
#include <string.h>

extern uint32_t _estack, _sidata, _sdata, _edata, _sbss, _ebss;
int main(void);

#define TIMER ((volatile uint32_t *)0x40000000u)   /* CMSDK APB timer 0: CTRL, VALUE, RELOAD */
#define TIMER_VALUE (TIMER[1])

static void semihost(uint32_t op, const void *arg) {
  register uint32_t r0 __asm__("r0") = op;
  register const void *r1 __asm__("r1") = arg;
  __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
}

static void put_row(char tag, uint32_t a, uint32_t b, uint32_t c, uint32_t d, uint32_t e) {
  const uint32_t v[5] = {a, b, c, d, e};
  char line[64];
  int i, j, n = 0;
  line[n++] = tag;
  for (i = 0; i < 5; ++i) {
    line[n++] = ' ';
    for (j = 7; j >= 0; --j) line[n++] = "0123456789abcdef"[(v[i] >> (4 * j)) & 15u];
  }
  line[n++] = '\n';
  line[n] = 0;
  semihost(0x04u, line);                 /* SYS_WRITE0 */
}

static void timer_start(void) {
  TIMER[2] = 0xFFFFFFFFu;
  TIMER[1] = 0xFFFFFFFFu;
  TIMER[0] = 1u;
}

static void pil_calibrate(uint32_t loops) {
  uint32_t a, b, empty;
  a = TIMER_VALUE;
  b = TIMER_VALUE;
  empty = a - b;
  a = TIMER_VALUE;
  __asm__ volatile("1: subs %0, %0, #1\n bne 1b" : "+r"(loops));
  b = TIMER_VALUE;
  put_row('C', empty, a - b, 0u, 0u, 0u);
}

void pil_reset(void) {
  uint32_t *src = &_sidata, *dst = &_sdata;
  static const uint32_t exit_block[2] = {0x20026u, 0u};   /* ADP_Stopped_ApplicationExit */
  while (dst < &_edata) *dst++ = *src++;
  for (dst = &_sbss; dst < &_ebss;) *dst++ = 0u;
  *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;        /* CPACR: the FPU on */
  __asm__ volatile("dsb\n isb");
  (void)main();
  semihost(0x18u, (const void *)exit_block[0]);           /* SYS_EXIT */
  for (;;) {
  }
}

__attribute__((section(".vectors"), used))
static const void *const pil_vectors[2] = {&_estack, (const void *)pil_reset};

"""

_LINKER_SCRIPT = """\
/* QEMU's MPS2 boards (AN386, AN500): 4 MB of code memory at 0, 4 MB of RAM at 0x20000000 */
MEMORY { CODE (rx) : ORIGIN = 0x00000000, LENGTH = 4M
         RAM (rwx) : ORIGIN = 0x20000000, LENGTH = 4M }
_estack = ORIGIN(RAM) + LENGTH(RAM);
SECTIONS {
  .text : { KEEP(*(.vectors)) *(.text*) *(.rodata*) . = ALIGN(4); } > CODE
  .ARM.exidx : { *(.ARM.exidx*) } > CODE
  _sidata = LOADADDR(.data);
  .data : { _sdata = .; *(.data*) . = ALIGN(4); _edata = .; } > RAM AT > CODE
  .bss (NOLOAD) : { _sbss = .; *(.bss*) *(COMMON) . = ALIGN(4); _ebss = .; } > RAM
}
"""

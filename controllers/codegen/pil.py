"""Processor in the loop: an export's step cross-compiled and run under QEMU on an MPS2 board.

Two ways: :func:`run_on_target` steps the law on recorded inputs and reads back its commands
and instruction counts; :class:`EmulatedLaw` keeps the emulated law running and steps it from
the host, one sample at a time over the board's UART, so that :func:`flexctl.simulate` flies
the plant on the host with the law on the target.

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

__all__ = ["run_on_target", "PILRun", "EmulatedLaw", "EmulationError", "find_emulator",
           "ICOUNT_SHIFT", "CALIBRATION_LOOPS", "CLOCKS", "BOARD_CLOCK_HZ"]

#: ``-icount shift``: 64 ns of virtual time per instruction, 1.6 ticks of the boards' 25 MHz
#: timer: the count resolves single instructions.
ICOUNT_SHIFT = 6
#: Iterations of the two-instruction loop that calibrates ticks per instruction.
CALIBRATION_LOOPS = 10000
#: Clocks (Hz) the instruction counts are turned into times at: a typical Cortex-M4F (STM32F4)
#: and Cortex-M7 (STM32H7, as issue 48 states 400 MHz).
CLOCKS = {"cortex-m4": 168e6, "cortex-m7": 400e6}
#: The MPS2 boards' system clock, Hz, which drives their timers.
BOARD_CLOCK_HZ = 25e6
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
        The step's command at each sample, in the law's output unit (its first entry, for a
        law of several: :attr:`outputs`).
    codes : ndarray of int, shape (K,)
        Its return codes.
    instructions : ndarray of int, shape (K,)
        Instructions each step executed (QEMU's count under ``-icount``; not cycles).
    ticks_per_instruction : float
        The calibration: timer ticks per instruction.
    clock_hz : float
        The clock of :attr:`time_estimate_s`.
    outputs : ndarray, shape (K, n_out)
        Every entry of the command at each sample (a three-axis law's three torques).
    """

    target: str
    board: str
    precision: str
    commands: np.ndarray
    codes: np.ndarray
    instructions: np.ndarray
    ticks_per_instruction: float
    clock_hz: float
    outputs: np.ndarray = None

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

    from .targets import check_target

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
    qemu = find_emulator()
    with tempfile.TemporaryDirectory(prefix="flexctl-pil-") as build:
        elf = _link(export, chosen, _program(export, times, inputs), Path(build))
        output = _emulate(qemu, chosen.board, elf)
    return _parse(output, chosen, export.precision, times.size,
                  clock_hz or CLOCKS[chosen.name], export.program.n_out)


def _link(export, target, main: str, folder: Path) -> Path:
    """``main`` (which includes the law's source) linked for ``target`` in ``folder``."""
    from .targets import find_target_compiler, run_tool, target_flags

    flags = [f for f in target_flags(target, export.precision)
             if not f.startswith(("-fstack-usage", "-fcallgraph"))]
    (folder / "pil.ld").write_text(_LINKER_SCRIPT, encoding="utf-8")
    (folder / "pil_main.c").write_text(main, encoding="utf-8")
    elf = folder / "pil.elf"
    run_tool([find_target_compiler(target), *flags, f"-I{Path(export.directory).resolve()}",
              "pil_main.c", "-nostartfiles", "-T", "pil.ld", "--specs=nano.specs",
              "--specs=nosys.specs",
              "-lm", "-o", elf], folder)
    return elf


class EmulatedLaw:
    """The step running under QEMU, stepped from the host: the plant on the host, the law on
    the emulated target (a :class:`~controllers.codegen.CompiledLaw`'s interface, so
    :class:`~controllers.codegen.export.CompiledController` closes the loop with it).

    The program on the target reads each request from the board's UART (CMSDK UART 0,
    QEMU's ``-serial stdio``): ``I`` (``flexctl_ctrl_init``) or ``S`` with the time and the
    input as the bits of each real, steps, and answers with the return code, the command's
    bits and the step's timer ticks (instructions, as in :func:`run_on_target`).

    Parameters
    ----------
    export : CExport
        The written export; its folder is only read.
    target : {"cortex-m4", "cortex-m7"}, optional
        The processor. Default ``"cortex-m4"``.

    Attributes
    ----------
    instructions : list of int
        Instructions of each step taken (timer ticks over ``ICOUNT_TICKS``).
    """

    def __init__(self, export, target: str = "cortex-m4"):
        from flexctl.model.errors import InputValueError

        from .targets import check_target

        chosen = check_target(target)
        if not chosen.embedded:
            raise InputValueError(f"processor in the loop target must be embedded, one of "
                                  f"{tuple(CLOCKS)}; got {target!r}")
        self.export, self.target, self.instructions = export, chosen, []
        qemu = find_emulator()
        self._folder = tempfile.TemporaryDirectory(prefix="flexctl-pil-loop-")
        elf = _link(export, chosen, _loop_program(export), Path(self._folder.name))
        self._process = subprocess.Popen(
            [qemu, "-M", chosen.board, "-display", "none", "-monitor", "none", "-serial",
             "stdio", "-semihosting-config", "enable=on,target=native",
             "-icount", f"shift={ICOUNT_SHIFT},align=off,sleep=off", "-kernel", str(elf)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self._wide = export.precision == "double"
        self._ticks = 2 ** ICOUNT_SHIFT * BOARD_CLOCK_HZ / 1e9
        self._answer()                       # "ready"

    @property
    def program(self):
        """The law's program."""
        return self.export.program

    def _answer(self) -> list:
        line = self._process.stdout.readline().decode("ascii", "replace").split()
        if not line:
            self.close()
            raise EmulationError(f"{EMULATOR} -M {self.target.board} stopped answering: "
                                 f"{self._process.stderr.read().decode()[-500:]!r}")
        return line

    def _send(self, text: str) -> list:
        self._process.stdin.write(text.encode("ascii") + b"\n")
        self._process.stdin.flush()
        return self._answer()

    def _bits(self, value: float) -> str:
        if self._wide:
            return f"{np.float64(value).view(np.uint64):016x}"
        return f"{int(np.float32(value).view(np.uint32)):016x}"

    def init(self) -> None:
        """``flexctl_ctrl_init`` on the target."""
        self._send("I")

    def step(self, t: float, v) -> tuple:
        """``flexctl_ctrl_step`` on the target: ``(u, code)``.

        Parameters
        ----------
        t : float
            Time, s.
        v : array_like, shape (n_in,)
            The step's input (plant state, or readings of a measurement law).
        """
        v = np.asarray(v, dtype=float).reshape(-1)
        code, high, low, ticks = (int(x, 16) for x in self._send(
            "S " + " ".join(self._bits(x) for x in (t, *v)))[1:5])
        self.instructions.append(int(round(ticks / self._ticks)))
        u = (np.uint64((high << 32) | low).view(np.float64) if self._wide
             else np.uint32(low).view(np.float32))
        return float(u), code

    def controller(self, measure=None):
        """This law as a flexctl controller
        (:class:`~controllers.codegen.export.CompiledController`).

        Parameters
        ----------
        measure : callable, optional
            ``measure(t, x) -> y`` for a measurement law. Default the program's matrix.
        """
        from .export import CompiledController

        return CompiledController(self, measure)

    def close(self) -> None:
        """Stop QEMU and remove the build."""
        if self._process.poll() is None:
            try:
                self._process.stdin.write(b"Q\n")
                self._process.stdin.flush()
                self._process.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self._process.kill()
                self._process.wait()
        self._folder.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _loop_program(export) -> str:
    return _PROGRAM_HEAD + textwrap.dedent(f"""\
        #include "{export.source.name}"

        #define UART ((volatile uint32_t *)0x40004000u)   /* CMSDK UART 0: DATA, STATE, CTRL */
        static struct flexctl_ctrl pil_ctrl;

        static void uart_put(char c) {{
          while (UART[1] & 1u) {{
          }}
          UART[0] = (uint32_t)(unsigned char)c;
        }}

        static int uart_get(void) {{
          while (!(UART[1] & 2u)) {{
          }}
          return (int)(UART[0] & 0xFFu);
        }}

        static void uart_word(uint32_t v) {{
          int j;
          uart_put(' ');
          for (j = 7; j >= 0; --j) uart_put("0123456789abcdef"[(v >> (4 * j)) & 15u]);
        }}

        /* one real as 16 hex digits (a float in the low 8) */
        static flexctl_real read_real(void) {{
          uint64_t bits = 0u;
          int j, c;
          flexctl_real value;
          while ((c = uart_get()) == ' ') {{
          }}
          for (j = 0; j < 16; ++j) {{
            if (j > 0) c = uart_get();
            bits = (bits << 4) | (uint64_t)(c <= '9' ? c - '0' : c - 'a' + 10);
          }}
          if (sizeof(flexctl_real) == 4) {{
            uint32_t low = (uint32_t)bits;
            memcpy(&value, &low, sizeof value);
          }} else {{
            memcpy(&value, &bits, sizeof value);
          }}
          return value;
        }}

        int main(void) {{
          flexctl_real t, v[FLEXCTL_N_INPUT], u = 0;
          uint32_t start, ticks, bits[2];
          int c, k, code;
          UART[4] = 16u;
          UART[2] = 3u;                       /* transmit and receive on */
          timer_start();
          pil_calibrate({CALIBRATION_LOOPS}u);     /* on semihosting's console, not read */
          uart_put('r');
          uart_put('\\n');
          for (;;) {{
            c = uart_get();
            if (c == 'Q') return 0;
            if (c == 'I') {{
              code = flexctl_ctrl_init(&pil_ctrl);
              ticks = 0u;
            }} else {{
              t = read_real();
              for (k = 0; k < FLEXCTL_N_INPUT; ++k) v[k] = read_real();
              start = TIMER_VALUE;
              code = flexctl_ctrl_step(&pil_ctrl, t, v, &u);
              ticks = start - TIMER_VALUE;
            }}
            while (c != '\\n') c = uart_get();
            bits[0] = bits[1] = 0u;
            memcpy(bits, &u, sizeof u);
            uart_put('R');
            uart_word((uint32_t)code);
            uart_word(bits[1]);
            uart_word(bits[0]);
            uart_word(ticks);
            uart_put('\\n');
          }}
        }}
        """)


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


def _real_bits(rows, precision) -> np.ndarray:
    """The reals of ``rows``' low and high words (columns 0 and 1)."""
    rows = np.asarray(rows, dtype=np.uint64).reshape(-1, 2)
    if precision == "float":
        return rows[:, 0].astype(np.uint32).view(np.float32).astype(float)
    return (rows[:, 0] | (rows[:, 1] << np.uint64(32))).view(np.float64).copy()


def _parse(output: str, target, precision: str, steps: int, clock_hz: float,
           n_out: int = 1) -> PILRun:
    calibration, rows, more = None, [], []
    for line in output.splitlines():
        parts = line.split()
        if parts[:1] == ["C"]:
            calibration = [int(p, 16) for p in parts[1:]]
        elif parts[:1] == ["S"]:
            rows.append([int(p, 16) for p in parts[1:]])
        elif parts[:1] == ["U"]:
            more.append([int(p, 16) for p in parts[1:]])
    if calibration is None or len(rows) != steps or len(more) != steps * (n_out - 1):
        raise EmulationError(f"the program under {EMULATOR} printed {len(rows)} of {steps} "
                             f"steps{'' if calibration else ' and no calibration'}: "
                             f"{output.strip()[-500:]!r}")
    empty, loop = calibration[:2]
    per_instruction = (loop - empty) / (2 * CALIBRATION_LOOPS)
    rows = np.array(rows, dtype=np.uint64)          # k, code, low bits, high bits, ticks
    outputs = np.empty((steps, n_out))
    outputs[:, 0] = _real_bits(rows[:, 2:4], precision)
    if n_out > 1:                                   # k, output, low bits, high bits, 0
        more = np.array(more, dtype=np.uint64)
        outputs[more[:, 0].astype(int), more[:, 1].astype(int)] = _real_bits(more[:, 2:4],
                                                                             precision)
    instructions = np.rint((rows[:, 4].astype(float) - empty) / per_instruction).astype(int)
    return PILRun(target.name, target.board, precision, outputs[:, 0].copy(),
                  rows[:, 1].astype(int), instructions, float(per_instruction),
                  float(clock_hz), outputs)


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
          int k, i, code;
          flexctl_real u[FLEXCTL_NU] = {{0}};
          timer_start();
          pil_calibrate({CALIBRATION_LOOPS}u);
          if (flexctl_ctrl_init(&pil_ctrl) != FLEXCTL_OK) return 1;
          for (k = 0; k < PIL_STEPS; ++k) {{
            start = TIMER_VALUE;
            code = flexctl_ctrl_step(&pil_ctrl, pil_times[k],
                                     &pil_inputs[k * FLEXCTL_N_INPUT], u);
            ticks = start - TIMER_VALUE;
            memcpy(bits, &u[0], sizeof u[0]);
            put_row('S', (uint32_t)k, (uint32_t)code, bits[0], bits[1], ticks);
            for (i = 1; i < FLEXCTL_NU; ++i) {{
              memcpy(bits, &u[i], sizeof u[i]);
              put_row('U', (uint32_t)k, (uint32_t)i, bits[0], bits[1], 0u);
            }}
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

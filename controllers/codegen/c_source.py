"""The C99 source, header, example ``main`` and Makefile of a :class:`ControllerProgram`.

The source holds CasADi's code for the program's step (and recover) functions and a thin
wrapper with the flexctl interface (see ``INTERFACE`` and the header it writes): an opaque
struct the caller allocates (``flexctl_ctrl_size()`` bytes, aligned for ``double``), which
holds the law's memory and every work array at a size fixed when the code was written. No
function allocates memory, nothing at file scope is mutable, and the math library is the only
dependency.
"""

from __future__ import annotations

import re
import textwrap

import numpy as np

from .precision import FLOAT_MIN, PRECISION_FLAGS, check_precision, single_precision_code
from .program import ControllerProgram

__all__ = ["CSources", "c_sources", "RETURN_CODES"]

#: The step's return codes: (macro, value, meaning).
RETURN_CODES = (
    ("FLEXCTL_OK", 0, "success: u is the law's command"),
    ("FLEXCTL_STEP_RECOVERED", 1, "the step's QP failed or gave a non-finite plan: u is the "
     "previous plan's next command (the plan shifted one sample), which the law keeps"),
    ("FLEXCTL_ERR_INPUT", 2, "t or an entry of x is not finite: u = 0, the memory unchanged"),
    ("FLEXCTL_ERR_FAILED", 3, "the law gave a non-finite command: u = 0, the memory unchanged"),
    ("FLEXCTL_ERR_ARGUMENT", 4, "a NULL pointer, or a struct not initialised by "
     "flexctl_ctrl_init: nothing is written"),
)

_MAGIC = 0x666C6578      # "flex"


class CSources:
    """The four files of an export, as text; made by :func:`c_sources`.

    Parameters
    ----------
    header : str
        The header ``<prefix>.h``: the struct and the functions' declarations.
    source : str
        The law ``<prefix>.c``: its generated step functions and their wrappers.
    main : str
        ``main.c``: an example program that runs the law on a state read from the command
        line and prints its command for ten samples.
    makefile : str
        The ``Makefile`` that builds the law as an object, a static library and the example
        program.
    sizes : dict
        ``memory_reals``, ``work_reals``, ``work_ints``, ``arg_pointers``,
        ``res_pointers``: the arrays of the struct, in entries (reals of the export's
        precision).
    """

    def __init__(self, header, source, main, makefile, sizes):
        self.header, self.source, self.main, self.makefile = header, source, main, makefile
        self.sizes = sizes


def _c_double(value: float, real: str = "double") -> str:
    if not np.isfinite(value):
        raise ValueError(f"cannot write the non-finite number {value!r} as C")
    if real == "float" and abs(value) < FLOAT_MIN:
        value = 0.0                      # float holds no such number (precision.FLOAT_MIN)
    return repr(float(value)) + ("f" if real == "float" else "")


def _array(values, real: str, per_line: int = 4) -> str:
    items = [_c_double(v, real) for v in np.asarray(values, dtype=float).reshape(-1)] or [
        _c_double(0.0, real)]
    lines = [", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    return "{\n  " + ",\n  ".join(lines) + "\n}"


def _generated(program: ControllerProgram, prefix: str, real: str) -> tuple:
    """CasADi's C for the step and recover functions, and the work sizes they need."""
    import casadi as ca

    cg = ca.CodeGenerator(f"{prefix}_casadi.c", {
        "with_header": False, "with_export": False, "verbose": False, "casadi_real": real,
        "casadi_int": "long long int", "prefix": f"{prefix}_", "avoid_stack": True})
    functions = [program.step] + ([program.recover] if program.recover is not None else [])
    renamed = [_renamed(function, f"{prefix}_{role}")
               for function, role in zip(functions, ("step", "recover"))]
    for function in renamed:
        cg.add(function)
    sizes = np.max([[f.sz_arg(), f.sz_res(), f.sz_iw(), f.sz_w()] for f in renamed], axis=0)
    code = cg.dump()
    if real == "float":
        code = single_precision_code(code)
    return code, [f.name() for f in renamed], [int(s) for s in sizes]


def _renamed(function, name):
    """``function`` under ``name`` (a call of it: the functions it calls stay shared)."""
    import casadi as ca

    args = function.sx_in() if function.is_a("SXFunction") else function.mx_in()
    return ca.Function(name, args, function.call(args), function.name_in(),
                       function.name_out())


def c_sources(program: ControllerProgram, prefix: str = "flexctl_ctrl",
              plant_states: int | None = None, precision: str = "double") -> CSources:
    """The C files of ``program`` (module docstring).

    Parameters
    ----------
    program : ControllerProgram
        The law's step functions.
    prefix : str, optional
        Prefix of the C names: lower-case letters, digits and ``_``, a letter first, at
        most 31 characters. Default ``"flexctl_ctrl"``.
    plant_states : int, optional
        The plant's state count, written as ``FLEXCTL_NX`` when the law reads readings.
        Default: the law's input count.
    precision : {"double", "float"}, optional
        The C type of every real (:mod:`~controllers.codegen.precision`). Default
        ``"double"``.

    Raises
    ------
    ValueError
        If ``prefix`` is not such a C identifier, or ``precision`` not a precision.
    """
    if not re.fullmatch(r"[a-z][a-z0-9_]{0,30}", prefix):
        raise ValueError(f"prefix must be a C identifier of lower-case letters, digits and _; "
                         f"got {prefix!r}")
    real = check_precision(precision)
    code, names, (sz_arg, sz_res, sz_iw, sz_w) = _generated(program, "flexctl_law", real)
    upper = prefix.upper()
    n_in, n_mem = program.n_in, program.n_memory
    measured = program.input_kind == "measurement"
    nx = plant_states if measured and plant_states else n_in
    sizes = {"memory_reals": n_mem, "work_reals": sz_w, "work_ints": sz_iw,
             "arg_pointers": sz_arg, "res_pointers": sz_res}
    header = _header(program, upper, prefix, nx, measured, real)
    source = _source(program, prefix, upper, code, names, sizes, real)
    return CSources(header, source, _main(program, prefix, upper), _makefile(prefix, real),
                    sizes)


def unit_of(name: str) -> str:
    """The unit of a state or reading by its name (``wing_a.q1_dot`` -> ``m/s``).

    Parameters
    ----------
    name : str
        A state or reading name, with or without an appendage prefix; ``""`` is returned
        for a name whose unit is not known.
    """
    base = name.rsplit(".", 1)[-1]
    rate = base.endswith("_dot")
    base = base[:-4] if rate else base
    if base in ("theta", "wheel_speed"):
        return "rad/s" if rate or base == "wheel_speed" else "rad"
    if base in ("root_moment", "wheel_torque"):
        return "N m"
    if base == "tip_acceleration":
        return "m/s^2"
    if base.startswith("hub_") or (base.startswith("q") and base[1:].isdigit()):
        return "m/s" if rate else "m"       # modal coordinates: metres at phi = 1
    return ""


def _names_comment(program) -> str:
    lines = []
    for i, name in enumerate(program.input_names):
        unit = unit_of(name)
        lines.append(f" *   [{i:2d}] {name}" + (f" ({unit})" if unit else ""))
    return "\n".join(lines)


def _wrapped(text: str) -> str:
    return "\n".join(" * " + line for line in textwrap.wrap(text, 88))


def _header(program, upper, prefix, nx, measured, real) -> str:
    kind = ("the sensor readings y (FLEXCTL_NY entries, below)" if measured else
            "FLEXCTL_NX plant states, in the plant's state order (below)")
    codes = "\n".join(f"#define {name} {value}   /* {text} */" for name, value, text in
                      RETURN_CODES)
    guard = f"{upper}_H"
    return f"""\
/* {prefix}.h: a flexctl feedback law as self-contained C99.
 *
{_wrapped(program.description)}
 * Input of the step: {kind}:
{_names_comment(program)}
 * Output u: the {program.output_name} ({program.output_unit}; FLEXCTL_NU entries).
 *
 * Every real is a flexctl_real ({real}). Usage: provide flexctl_ctrl_size() bytes aligned for
 * double (malloc, or a static array of double), call flexctl_ctrl_init once, then
 * flexctl_ctrl_step at every sample time t (t_0, t_0 + FLEXCTL_SAMPLE_TIME, ...), or
 * whenever a command is needed when FLEXCTL_SAMPLE_TIME is 0. The struct holds the law's
 * memory: one struct per loop, no global state, no allocation.
 */
#ifndef {guard}
#define {guard}

#include <stddef.h>

#ifdef __cplusplus
extern "C" {{
#endif

#define FLEXCTL_NX {nx}   /* plant states{'' if measured else ' the law reads, in the plant state order'} */
#define FLEXCTL_NY {program.n_in if measured else 0}   /* sensor readings an output-feedback law reads (0: it reads the state) */
#define FLEXCTL_N_INPUT {program.n_in}   /* entries of the step's input (FLEXCTL_NY if nonzero, else FLEXCTL_NX) */
#define FLEXCTL_NU {program.n_out}   /* entries of the command u */
#define FLEXCTL_SAMPLE_TIME {_c_double(program.sample_time, real)}   /* s; 0 for a continuous law evaluated when called */
#define FLEXCTL_MEMORY_REALS {program.n_memory}   /* the law's memory, inside the struct */
#define FLEXCTL_PRECISION "{real}"

typedef {real} flexctl_real;   /* the type of every real of the law */

{codes}

typedef struct flexctl_ctrl flexctl_ctrl;   /* opaque */

/* Bytes the caller provides for one controller. */
size_t flexctl_ctrl_size(void);

/* Sets the law's memory to its start (estimate, warm start, last command); 0 on success,
 * FLEXCTL_ERR_ARGUMENT for a NULL pointer. Call again to restart the law. */
int flexctl_ctrl_init(flexctl_ctrl *c);

/* u[0..FLEXCTL_NU-1]: the command to hold from time t (s), given x (FLEXCTL_N_INPUT entries:
 * the plant state, or the readings y of an output-feedback law). Returns one of the codes
 * above. */
int flexctl_ctrl_step(flexctl_ctrl *c, flexctl_real t, const flexctl_real *x, flexctl_real *u);

/* Names of the step's input entries, in order. */
extern const char *const flexctl_ctrl_input_names[FLEXCTL_N_INPUT];

#ifdef __cplusplus
}}
#endif

#endif
"""


def _source(program, prefix, upper, code, names, sizes, real) -> str:
    has_recover = program.recover is not None
    recover_block = ""
    if has_recover:
        recover_block = f"""
  if (!ok) {{
    /* the step failed: the previous plan, shifted one sample */
    c->arg[0] = &t;
    c->arg[1] = x;
    c->arg[2] = c->m;
    c->res[0] = u_new;
    c->res[1] = c->m_next;
    flag = {names[1]}(c->arg, c->res, c->iw, c->w, 0);
    ok = flag == 0 && flexctl_finite(u_new, FLEXCTL_NU) && flexctl_finite(c->m_next, FLEXCTL_MEMORY_REALS);
    status = FLEXCTL_STEP_RECOVERED;
  }}"""
    return f"""\
/* {prefix}.c: a flexctl feedback law as self-contained C99.
{_wrapped(program.description)}
 * Written by flexctl from its CasADi form; C99, no allocation, no mutable file-scope state.
 */
#include "{prefix}.h"

#include <math.h>
#include <string.h>

/* ----------------------------------------------------------------------------------------
 * CasADi's code of the law's step{' and recover' if has_recover else ''} function{'s' if has_recover else ''}.
 * CasADi writes every entry point with the same parameter list and some of them leave
 * parameters unread; only that warning is silenced here, for this part alone.
 */
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif
{code}
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

{_wrapper(program, sizes, real)}
int flexctl_ctrl_step(flexctl_ctrl *c, flexctl_real t, const flexctl_real *x, flexctl_real *u) {{
  flexctl_real u_new[FLEXCTL_NU] = {{0}};
  int i, flag, ok, status = FLEXCTL_OK;
  if (!c || !x || !u || c->magic != FLEXCTL_MAGIC) return FLEXCTL_ERR_ARGUMENT;
  if (!isfinite(t) || !flexctl_finite(x, FLEXCTL_N_INPUT)) {{
    for (i = 0; i < FLEXCTL_NU; ++i) u[i] = 0;
    return FLEXCTL_ERR_INPUT;
  }}
  c->arg[0] = &t;
  c->arg[1] = x;
  c->arg[2] = c->m;
  c->res[0] = u_new;
  c->res[1] = c->m_next;
  flag = {names[0]}(c->arg, c->res, c->iw, c->w, 0);
  ok = flag == 0 && flexctl_finite(u_new, FLEXCTL_NU) && flexctl_finite(c->m_next, FLEXCTL_MEMORY_REALS);{recover_block}
  if (!ok) {{
    for (i = 0; i < FLEXCTL_NU; ++i) u[i] = 0;
    return FLEXCTL_ERR_FAILED;
  }}
  memcpy(c->m, c->m_next, sizeof(c->m));
  for (i = 0; i < FLEXCTL_NU; ++i) u[i] = u_new[i];
  return status;
}}
"""


def _wrapper(program, sizes, real) -> str:
    """The struct, its initial memory, the input names, ``size`` and ``init``."""
    n_mem = max(program.n_memory, 1)
    names_list = ",\n  ".join(f'"{name}"' for name in program.input_names)
    return f"""\
/* ---------------------------------------------------------------------------------------- */
#define FLEXCTL_SZ_ARG {max(sizes['arg_pointers'], 1)}
#define FLEXCTL_SZ_RES {max(sizes['res_pointers'], 1)}
#define FLEXCTL_SZ_IW {max(sizes['work_ints'], 1)}
#define FLEXCTL_SZ_W {max(sizes['work_reals'], 1)}
#define FLEXCTL_MAGIC {_MAGIC}

struct flexctl_ctrl {{
  flexctl_real m[{n_mem}];        /* the law's memory */
  flexctl_real m_next[{n_mem}];   /* the memory after the step being taken */
  flexctl_real w[FLEXCTL_SZ_W];
  long long int iw[FLEXCTL_SZ_IW];
  const flexctl_real *arg[FLEXCTL_SZ_ARG];
  flexctl_real *res[FLEXCTL_SZ_RES];
  long magic;
}};

static const flexctl_real flexctl_m0[{n_mem}] = {_array(program.memory_init if program.n_memory else [0.0], real)};

const char *const flexctl_ctrl_input_names[FLEXCTL_N_INPUT] = {{
  {names_list}
}};

static int flexctl_finite(const flexctl_real *v, int n) {{
  int i;
  for (i = 0; i < n; ++i) {{
    if (!isfinite(v[i])) return 0;
  }}
  return 1;
}}

size_t flexctl_ctrl_size(void) {{
  return sizeof(struct flexctl_ctrl);
}}

int flexctl_ctrl_init(flexctl_ctrl *c) {{
  if (!c) return FLEXCTL_ERR_ARGUMENT;
  memset(c, 0, sizeof(struct flexctl_ctrl));
  memcpy(c->m, flexctl_m0, sizeof(flexctl_m0));
  c->magic = FLEXCTL_MAGIC;
  return FLEXCTL_OK;
}}

"""


def _main(program, prefix, upper) -> str:
    return f"""\
/* main.c: runs the exported law on a state read from the command line (or zeros), and
 * prints its command for ten samples. Build: make; run: ./{prefix}_demo [x_0 x_1 ...] */
#include <stdio.h>
#include <stdlib.h>

#include "{prefix}.h"

int main(int argc, char **argv) {{
  flexctl_real x[FLEXCTL_N_INPUT] = {{0}};
  flexctl_real u[FLEXCTL_NU] = {{0}};
  int i, k, code;
  flexctl_ctrl *c = (flexctl_ctrl *)malloc(flexctl_ctrl_size());   /* once, before the loop */
  if (!c) return 1;
  for (i = 0; i < FLEXCTL_N_INPUT && i + 1 < argc; ++i) x[i] = (flexctl_real)atof(argv[i + 1]);
  if (flexctl_ctrl_init(c) != FLEXCTL_OK) return 1;
  for (k = 0; k < 10; ++k) {{
    flexctl_real t = (flexctl_real)k * (FLEXCTL_SAMPLE_TIME > 0 ? FLEXCTL_SAMPLE_TIME
                                                         : (flexctl_real)0.01);
    code = flexctl_ctrl_step(c, t, x, u);
    printf("t = %.4f s  u[0] = %.12g  (code %d)\\n", (double)t, (double)u[0], code);
  }}
  printf("controller struct: %lu bytes\\n", (unsigned long)flexctl_ctrl_size());
  free(c);
  return 0;
}}
"""


def _makefile(prefix, real) -> str:
    from .targets import TARGETS, target_flags

    extra = "".join(" " + flag for flag in PRECISION_FLAGS[real])
    embedded = [target for target in TARGETS.values() if target.embedded]
    rules = "".join(
        f"\n# {t.name}: the law as a static library for a {t.name}, built freestanding at "
        f"the flags\n# flexctl checks it with (each function's stack use in "
        f"{prefix}_{t.name}.su)\n"
        f"{t.name}: lib{prefix}_{t.name}.a\n\n"
        f"lib{prefix}_{t.name}.a: {prefix}.c {prefix}.h\n"
        f"\t{t.compiler} {' '.join(target_flags(t, real))} -c {prefix}.c "
        f"-o {prefix}_{t.name}.o\n"
        f"\t{t.tools}ar rcs $@ {prefix}_{t.name}.o\n" for t in embedded)
    names = " ".join(t.name for t in embedded)
    cleaned = " ".join(f"{prefix}_{t.name}.o lib{prefix}_{t.name}.a" for t in embedded)
    return textwrap.dedent(f"""\
        # Builds the exported law as an object, a static library and the example program.
        CC ?= cc
        CFLAGS ?= -std=c99 -O2 -Wall -Wextra -Werror{extra}
        LDLIBS = -lm

        all: lib{prefix}.a {prefix}_demo

        {prefix}.o: {prefix}.c {prefix}.h
        \t$(CC) $(CFLAGS) -c {prefix}.c -o $@

        lib{prefix}.a: {prefix}.o
        \t$(AR) rcs $@ $^

        {prefix}_demo: main.c lib{prefix}.a
        \t$(CC) $(CFLAGS) main.c lib{prefix}.a $(LDLIBS) -o $@

        clean:
        \trm -f {prefix}.o lib{prefix}.a {prefix}_demo {cleaned} *.su *.ci

        .PHONY: all clean {names}
        """) + rules

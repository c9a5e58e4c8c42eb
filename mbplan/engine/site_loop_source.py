"""C source of ``<name>_sites``: a CasADi function evaluated at ``K`` sites in one C call.

Argument ``i`` and result ``i`` of site ``k`` are at ``arg[i] + k * nnz_in(i)`` and
``res[i] + k * nnz_out(i)`` (C-ordered ``(K, nnz)`` arrays). Two forms:

* **vectorized**, when CasADi's code of the function is straight-line scalar arithmetic (SX:
  assignments of local variables from the arguments, constants and each other, with
  ``casadi_sq``, ``casadi_fabs`` and ``sqrt`` the only calls): the sites go in chunks of
  :data:`SITE_CHUNK`; a chunk's arguments are transposed into site-minor scratch arrays, the
  function's statements run once for the whole chunk in a ``#pragma omp simd`` loop (one SIMD
  lane per site) and the results are transposed back. The same operations per site as the
  scalar code, except that the compiler may fuse a multiply and an add where the scalar code
  calls ``casadi_sq`` (a difference in the last bit); a partial last chunk fills its idle lanes
  with the chunk's first site and stores only its own sites;
* **scalar** otherwise (other calls, work vectors, a result entry not written exactly once, or
  scratch beyond :data:`STACK_MAX` bytes): CasADi's function called once per site.
"""

from __future__ import annotations

import hashlib
import re
from importlib import resources

import casadi as cs

SITE_CHUNK = 8
"""Sites per SIMD chunk: one AVX-512 vector of doubles (two AVX2 vectors)."""

STACK_MAX = 1 << 18
"""Largest stack scratch of a vectorized loop (bytes: a chunk of every argument, result and
local variable); a larger function keeps the scalar loop."""

_INLINE = {"casadi_sq": None, "casadi_fabs": "fabs"}
"""CasADi's helper functions in a vectorized body, written inline (``None``: ``(a*a)``)."""

_NAMES = frozenset({"sqrt", "fabs", "casadi_inf", "casadi_nan"})
"""Names other than local variables a rewritten statement may contain."""

COMPILE_FLAGS = ("-fopenmp-simd", "-fno-math-errno")
"""What the vectorized loop needs of the C compiler, besides optimization (``sqrt`` inline)."""

_SCALAR = """
int {name}_sites(casadi_int K, const casadi_real** arg, casadi_real** res) {{
  static const casadi_int nnz_in[] = {{{nnz_in}}}, nnz_out[] = {{{nnz_out}}};
  casadi_int sz_arg, sz_res, sz_iw, sz_w, i, k;
  {name}_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real* a[sz_arg + 1];
  casadi_real* r[sz_res + 1];
  casadi_int iw[sz_iw + 1];
  casadi_real w[sz_w + 1];
  for (i = 0; i < sz_arg; ++i) a[i] = 0;
  for (i = 0; i < sz_res; ++i) r[i] = 0;
  for (k = 0; k < K; ++k) {{
    for (i = 0; i < {n_in}; ++i) a[i] = arg[i] ? arg[i] + k * nnz_in[i] : 0;
    for (i = 0; i < {n_out}; ++i) r[i] = res[i] ? res[i] + k * nnz_out[i] : 0;
    if ({name}(a, r, iw, w, 0)) return 1;
  }}
  return 0;
}}
"""

_BODY_START = (
    "static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw, "
    "casadi_real* w, int mem) {\n"
)
_DECLARATION = re.compile(r"casadi_real ((?:a\d+, )*a\d+);")
_ARG = re.compile(r"(a\d+)=arg\[(\d+)\]\? arg\[\2\]\[(\d+)\] : 0;")
_RES = re.compile(r"if \(res\[(\d+)\]!=0\) res\[\1\]\[(\d+)\]=([^;\[\]]+);")
_ASSIGN = re.compile(r"(a\d+)=([^;\[\]]+);")
_HELPER = re.compile(r"\b(casadi_sq|casadi_fabs)\((a\d+)\)")
_NAME = re.compile(r"\b[A-Za-z_]\w*")
_LOCAL = re.compile(r"a\d+")

GENERATOR_KEY = hashlib.sha256(
    resources.files(__package__).joinpath("site_loop_source.py").read_bytes()
).hexdigest()
"""The hash of this module's source: what the generated loops depend on besides the function
(part of the compiled objects' cache key)."""


def site_loop_source(fn: cs.Function, casadi_source: str) -> str:
    """``<name>_sites`` for ``fn``, whose CasADi-generated C is ``casadi_source``: vectorized
    if its body allows (module docstring), else the scalar loop."""
    nnz_in = [fn.nnz_in(i) for i in range(fn.n_in())]
    nnz_out = [fn.nnz_out(i) for i in range(fn.n_out())]
    statements = _vector_statements(casadi_source, nnz_in, nnz_out)
    if statements is None:
        return _scalar_source(fn.name(), nnz_in, nnz_out)
    return _vector_source(fn.name(), nnz_in, nnz_out, *statements)


def _scalar_source(name: str, nnz_in: list[int], nnz_out: list[int]) -> str:
    def sizes(nnz: list[int]) -> str:
        return ", ".join(map(str, nnz)) or "0"

    return _SCALAR.format(
        name=name,
        n_in=len(nnz_in),
        n_out=len(nnz_out),
        nnz_in=sizes(nnz_in),
        nnz_out=sizes(nnz_out),
    )


def _vector_statements(
    source: str, nnz_in: list[int], nnz_out: list[int]
) -> tuple[list[str], list[str]] | None:
    """The declarations and the statements of the function's body rewritten for a chunk (site
    ``c`` of argument ``i``'s entry ``j`` at ``x{i}[j * SITE_CHUNK + c]``, results in ``y{i}``),
    or ``None`` if the body is not straight-line arithmetic of the allowed names, reads an
    argument entry that does not exist, does not write every result entry exactly once or
    needs more than :data:`STACK_MAX` bytes of scratch."""
    parts = source.split(_BODY_START)
    if len(parts) != 2 or "\n}\n" not in parts[1]:
        return None
    lines = [line.strip() for line in parts[1].split("\n}\n", 1)[0].split("\n")]
    lines = [line for line in lines if line]
    if not lines or lines.pop() != "return 0;":
        return None
    declarations, statements, written, n_local = [], [], [], 0
    for s in lines:
        if m := _DECLARATION.fullmatch(s):
            declarations.append(s)
            n_local += m[1].count(",") + 1
        elif m := _ARG.fullmatch(s):
            if int(m[2]) >= len(nnz_in) or int(m[3]) >= nnz_in[int(m[2])]:
                return None
            statements.append(f"{m[1]}=x{m[2]}[{m[3]}*{SITE_CHUNK}+c];")
        elif m := _RES.fullmatch(s):
            value = _inline(m[3])
            if value is None:
                return None
            statements.append(f"y{m[1]}[{m[2]}*{SITE_CHUNK}+c]={value};")
            written.append((int(m[1]), int(m[2])))
        elif (m := _ASSIGN.fullmatch(s)) and (value := _inline(m[2])) is not None:
            statements.append(f"{m[1]}={value};")
        else:
            return None
    if sorted(written) != [(i, j) for i, q in enumerate(nnz_out) for j in range(q)]:
        return None
    if 8 * SITE_CHUNK * (sum(nnz_in) + sum(nnz_out) + n_local) > STACK_MAX:
        return None
    return declarations, statements


def _inline(expression: str) -> str | None:
    """``expression`` with CasADi's helpers written inline (``casadi_sq(a)`` as ``(a*a)``,
    ``casadi_fabs`` as ``fabs``), or ``None`` if it then names anything but local variables and
    :data:`_NAMES`."""

    def helper(m: re.Match) -> str:
        name = _INLINE[m[1]]
        return f"({m[2]}*{m[2]})" if name is None else f"{name}({m[2]})"

    expression = _HELPER.sub(helper, expression)
    if any(not _LOCAL.fullmatch(n) and n not in _NAMES for n in _NAME.findall(expression)):
        return None
    return expression


def _vector_source(
    name: str, nnz_in: list[int], nnz_out: list[int], declarations: list[str], statements: list[str]
) -> str:
    """The chunked loop (module docstring) around the rewritten body."""
    C = SITE_CHUNK
    lines = [
        f"int {name}_sites(casadi_int K, const casadi_real** arg, casadi_real** res) {{",
        "  casadi_int k0, c, j, n;",
        *(f"  casadi_real x{i}[{max(q, 1) * C}];" for i, q in enumerate(nnz_in)),
        *(f"  casadi_real y{i}[{max(q, 1) * C}];" for i, q in enumerate(nnz_out)),
        f"  for (k0 = 0; k0 < K; k0 += {C}) {{",
        f"    n = K - k0 < {C} ? K - k0 : {C};",
    ]
    for i, q in enumerate(nnz_in):
        if q:
            lines += [
                f"    if (arg[{i}]) {{",
                f"      for (c = 0; c < {C}; ++c) {{",
                f"        const casadi_real* s = arg[{i}] + (k0 + (c < n ? c : 0)) * {q};",
                f"        for (j = 0; j < {q}; ++j) x{i}[j * {C} + c] = s[j];",
                "      }",
                f"    }} else {{ for (j = 0; j < {q * C}; ++j) x{i}[j] = 0; }}",
            ]
    lines += [
        "    #pragma omp simd",
        f"    for (c = 0; c < {C}; ++c) {{",
        *(f"      {d}" for d in declarations),
        *(f"      {s}" for s in statements),
        "    }",
    ]
    for i, q in enumerate(nnz_out):
        if q:
            lines += [
                f"    if (res[{i}]) {{",
                f"      casadi_real* r = res[{i}] + k0 * {q};",
                "      for (c = 0; c < n; ++c)",
                f"        for (j = 0; j < {q}; ++j) r[c * {q} + j] = y{i}[j * {C} + c];",
                "    }",
            ]
    lines += ["  }", "  return 0;", "}", ""]
    return "\n".join(lines)

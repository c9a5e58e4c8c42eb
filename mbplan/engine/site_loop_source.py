"""C source of ``<name>_sites``: a CasADi function evaluated at ``K`` sites in one C call.

Argument ``i`` and result ``i`` of site ``k`` are at ``arg[i] + k * nnz_in(i)`` and
``res[i] + k * nnz_out(i)`` (C-ordered ``(K, nnz)`` arrays). Two forms:

* **vectorized**, when CasADi's code of the function is straight-line scalar arithmetic (SX:
  assignments of local variables, ``casadi_sq``, ``sqrt``, ``fabs``, ``fmin``, ``fmax``):
  the sites go in chunks of :data:`SITE_CHUNK`; a chunk's arguments are transposed into
  site-minor scratch arrays, the function's statements run once for the whole chunk in a
  ``#pragma omp simd`` loop (one SIMD lane per site) and the results are transposed back. The
  same operations in the same order per site as the scalar code; a partial last chunk fills
  its idle lanes with the chunk's first site and stores only its own sites;
* **scalar** otherwise: CasADi's function called once per site.
"""

from __future__ import annotations

import re
from pathlib import Path

import casadi as cs

SITE_CHUNK = 8
"""Sites per SIMD chunk: one AVX-512 vector of doubles (two AVX2 vectors)."""

VECTOR_CALLS = frozenset({"casadi_sq", "sqrt", "fabs", "fmin", "fmax"})
"""Calls a vectorized site loop may contain (compiled inline by ``-fno-math-errno``)."""

COMPILE_FLAGS = ("-fopenmp-simd", "-fno-math-errno")
"""What the vectorized loop needs of the C compiler, besides optimization."""

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
    for (i = 0; i < {n_in}; ++i) a[i] = arg[i] + k * nnz_in[i];
    for (i = 0; i < {n_out}; ++i) r[i] = res[i] + k * nnz_out[i];
    if ({name}(a, r, iw, w, 0)) return 1;
  }}
  return 0;
}}
"""

_BODY_START = (
    "static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw, "
    "casadi_real* w, int mem) {\n"
)
_BODY_END = "\n  return 0;\n}\n"
_ARG = re.compile(r"(a\d+)=arg\[(\d+)\]\? arg\[\2\]\[(\d+)\] : 0;")
_RES = re.compile(r"if \(res\[(\d+)\]!=0\) res\[\1\]\[(\d+)\]=([^;\[\]]+);")
_ASSIGN = re.compile(r"a\d+=[^;\[\]]+;")
_CALL = re.compile(r"([A-Za-z_]\w*)\(")
_SQ = re.compile(r"casadi_sq\((a\d+)\)")

GENERATOR_KEY = Path(__file__).read_text()
"""This module's source: what the generated loops depend on besides the function (part of the
compiled objects' cache key)."""


def site_loop_source(fn: cs.Function, casadi_source: str) -> str:
    """``<name>_sites`` for ``fn``, whose CasADi-generated C is ``casadi_source``: vectorized
    if its body allows (module docstring), else the scalar loop."""
    statements = _vector_statements(casadi_source, [fn.nnz_out(i) for i in range(fn.n_out())])
    if statements is None:
        return _scalar_source(fn)
    return _vector_source(fn, *statements)


def _scalar_source(fn: cs.Function) -> str:
    def sizes(n: int, nnz) -> str:
        return ", ".join(str(nnz(i)) for i in range(n)) or "0"

    return _SCALAR.format(
        name=fn.name(),
        n_in=fn.n_in(),
        n_out=fn.n_out(),
        nnz_in=sizes(fn.n_in(), fn.nnz_in),
        nnz_out=sizes(fn.n_out(), fn.nnz_out),
    )


def _vector_statements(source: str, nnz_out: list[int]) -> tuple[list[str], list[str]] | None:
    """The declarations and the statements of the function's body rewritten for a chunk (site
    ``c`` of argument ``i``'s entry ``j`` at ``x{i}[j * SITE_CHUNK + c]``, results in ``y{i}``),
    or ``None`` if the body is not straight-line arithmetic of the allowed calls or does not
    write every result entry (``nnz_out``) exactly once."""
    parts = source.split(_BODY_START)
    if len(parts) != 2 or _BODY_END not in parts[1]:
        return None
    declarations, statements, written = [], [], []
    for line in parts[1].split(_BODY_END, 1)[0].split("\n"):
        s = line.strip()
        if not s:
            continue
        if s.startswith("casadi_real ") and re.fullmatch(r"casadi_real (a\d+, )*a\d+;", s):
            declarations.append(s)
        elif m := _ARG.fullmatch(s):
            statements.append(f"{m[1]}=x{m[2]}[{m[3]}*{SITE_CHUNK}+c];")
        elif m := _RES.fullmatch(s):
            if not set(_CALL.findall(m[3])) <= VECTOR_CALLS:
                return None
            statements.append(f"y{m[1]}[{m[2]}*{SITE_CHUNK}+c]={_squares(m[3])};")
            written.append((int(m[1]), int(m[2])))
        elif _ASSIGN.fullmatch(s) and set(_CALL.findall(s)) <= VECTOR_CALLS:
            statements.append(_squares(s))
        else:
            return None
    if sorted(written) != [(i, j) for i, q in enumerate(nnz_out) for j in range(q)]:
        return None
    return declarations, statements


def _squares(expression: str) -> str:
    """``casadi_sq(a)`` written as ``(a*a)`` (CasADi's inline helper, for the vectorizer)."""
    return _SQ.sub(r"(\1*\1)", expression)


def _vector_source(fn: cs.Function, declarations: list[str], statements: list[str]) -> str:
    """The chunked loop (module docstring) around the rewritten body."""
    C = SITE_CHUNK
    nnz_in = [fn.nnz_in(i) for i in range(fn.n_in())]
    nnz_out = [fn.nnz_out(i) for i in range(fn.n_out())]
    lines = [
        f"int {fn.name()}_sites(casadi_int K, const casadi_real** arg, casadi_real** res) {{",
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

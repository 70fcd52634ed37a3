"""A CasADi SX Function as plain JSON data, and back: how a found effect's acceleration travels
in a stage file (:mod:`maglev_oc.model.stagefile`) without pickles or CasADi's binary serialization.

The data is the Function's algorithm, one instruction a line, with operations by name:

    {"inputs": {"x": 4, "u": 2}, "outputs": {"acc": 2}, "work": 7,
     "algorithm": [["input", 0, "x", 0], ["const", 1, 3.5], ["mul", 2, 0, 1], ["sin", 3, 2],
                   ["output", "acc", 0, 3], ...]}

``["op", w, a]`` / ``["op", w, a, b]`` set work cell ``w`` to op(cell a[, cell b]);
``["const", w, value]`` a constant (``"inf"``, ``"-inf"`` for the infinities);
``["input", w, name, k]`` element k of an input; ``["output", name, k, w]`` element k of an
output (elements never set are zero). Only elementwise arithmetic is accepted (no calls to
other Functions, no external code): a file can describe a formula, never run a program.
Constants are written with ``repr`` precision, so a Function read back evaluates bit-identically.
Inputs and outputs are dense column vectors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import casadi as ca

from maglev_oc.errors import InputError

__all__ = ["MAX_INSTRUCTIONS", "function_from_data", "function_to_data"]

MAX_INSTRUCTIONS = 200_000
"""A found effect's acceleration is a few hundred to a few thousand instructions; refuse more."""

_UNARY = (
    "assign neg exp log sqrt sq twice sin cos tan asin acos atan not floor ceil fabs sign erf inv "
    "sinh cosh tanh asinh acosh atanh erfinv expm1 log1p"
).split()
_BINARY = (
    "add sub mul div pow constpow lt le eq ne and or fmod copysign if_else_zero fmin fmax atan2 "
    "hypot remainder"
).split()
_OPS = {
    name: getattr(ca, f"OP_{name.upper()}")
    for name in (*_UNARY, *_BINARY)
    if hasattr(ca, f"OP_{name.upper()}")
}
_NAMES = {code: name for name, code in _OPS.items()}
_ARITY = {**dict.fromkeys(_UNARY, 1), **dict.fromkeys(_BINARY, 2)}


def function_to_data(fn: ca.Function) -> dict[str, Any]:
    """``fn`` (an SX Function of dense column vectors) as JSON data (see the module doc).

    Raises
    ------
    InputError
        ``fn`` is not an SX Function of dense vectors, or uses an operation this format does
        not hold (a call to another Function).
    """
    if not fn.is_a("SXFunction"):
        fn = fn.expand()
    inputs = {fn.name_in(k): fn.size1_in(k) for k in range(fn.n_in())}
    outputs = {fn.name_out(k): fn.size1_out(k) for k in range(fn.n_out())}
    for k in range(fn.n_in()):
        if fn.size2_in(k) != 1 or not fn.sparsity_in(k).is_dense():
            raise InputError(f"{fn.name()}: input {fn.name_in(k)} must be a dense column vector")
    rows_out = [fn.sparsity_out(k).row() for k in range(fn.n_out())]
    for k in range(fn.n_out()):
        if fn.size2_out(k) != 1:
            raise InputError(f"{fn.name()}: output {fn.name_out(k)} must be a column vector")
    algorithm: list[list[Any]] = []
    work = 0
    for i in range(fn.n_instructions()):
        op, args, res = fn.instruction_id(i), fn.instruction_input(i), fn.instruction_output(i)
        if op == ca.OP_CONST:
            value = fn.instruction_constant(i)
            algorithm.append(["const", res[0], value if math.isfinite(value) else str(value)])
        elif op == ca.OP_INPUT:
            algorithm.append(["input", res[0], fn.name_in(args[0]), args[1]])
        elif op == ca.OP_OUTPUT:
            algorithm.append(["output", fn.name_out(res[0]), rows_out[res[0]][res[1]], args[0]])
            continue
        elif op in _NAMES:
            name = _NAMES[op]
            algorithm.append([name, res[0], *args[: _ARITY[name]]])
        else:
            raise InputError(f"{fn.name()}: operation {op} (instruction {i}) cannot be written as data")
        work = max(work, res[0] + 1)
    return {"inputs": inputs, "outputs": outputs, "work": work, "algorithm": algorithm}


def _int(value: Any, where: str, upper: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where}: expected an integer, got {value!r}")
    if not 0 <= value < upper:
        raise InputError(f"{where}: {value} is out of range [0, {upper})")
    return value


def _sizes(data: Any, where: str) -> dict[str, int]:
    if not isinstance(data, Mapping) or not data:
        raise InputError(f"{where}: expected a non-empty object name -> size")
    out = {}
    for name, size in data.items():
        out[name] = _int(size, f"{where}.{name}", 10_000)
        if out[name] == 0:
            raise InputError(f"{where}.{name}: a size must be positive")
    return out


def function_from_data(data: Any, name: str, where: str) -> ca.Function:
    """The Function ``data`` describes (as written by :func:`function_to_data`).

    Parameters
    ----------
    data : the JSON value
    name : str
        Name of the Function.
    where : str
        Prefix of error messages (the file and the field path).

    Raises
    ------
    InputError
        Anything malformed, naming the instruction and the element at fault.
    """
    if not isinstance(data, Mapping):
        raise InputError(f"{where}: expected an object, got {type(data).__name__}")
    missing = [k for k in ("inputs", "outputs", "work", "algorithm") if k not in data]
    if missing:
        raise InputError(f"{where}: missing {', '.join(missing)}")
    unknown = sorted(set(data) - {"inputs", "outputs", "work", "algorithm"})
    if unknown:
        raise InputError(f"{where}: unknown key(s) {unknown}")
    inputs, outputs = _sizes(data["inputs"], f"{where}.inputs"), _sizes(data["outputs"], f"{where}.outputs")
    n_work = _int(data["work"], f"{where}.work", MAX_INSTRUCTIONS + 1)
    algorithm = data["algorithm"]
    if not isinstance(algorithm, list) or len(algorithm) > MAX_INSTRUCTIONS:
        raise InputError(f"{where}.algorithm: expected a list of at most {MAX_INSTRUCTIONS} instructions")
    symbols = {k: ca.SX.sym(k, n) for k, n in inputs.items()}
    out = {k: [ca.SX(0)] * n for k, n in outputs.items()}
    cells: list[ca.SX | None] = [None] * n_work

    def operand(value: Any, at: str) -> ca.SX:
        k = _int(value, at, n_work)
        if cells[k] is None:
            raise InputError(f"{at}: work cell {k} is read before it is set")
        return cells[k]

    for i, ins in enumerate(algorithm):
        at = f"{where}.algorithm[{i}]"
        if not isinstance(ins, list) or not ins or not isinstance(ins[0], str):
            raise InputError(f"{at}: expected [operation, ...], got {ins!r}")
        op = ins[0]
        if op == "const":
            if len(ins) != 3:
                raise InputError(f"{at}: expected ['const', cell, value]")
            value = ins[2]
            if value in ("inf", "-inf"):
                value = float(value)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
                raise InputError(f"{at}[2]: expected a number, got {ins[2]!r}")
            cells[_int(ins[1], f"{at}[1]", n_work)] = ca.SX(float(value))
        elif op == "input":
            if len(ins) != 4 or ins[2] not in inputs:
                raise InputError(f"{at}: expected ['input', cell, one of {sorted(inputs)}, element]")
            element = _int(ins[3], f"{at}[3]", inputs[ins[2]])
            cells[_int(ins[1], f"{at}[1]", n_work)] = symbols[ins[2]][element]
        elif op == "output":
            if len(ins) != 4 or ins[1] not in outputs:
                raise InputError(f"{at}: expected ['output', one of {sorted(outputs)}, element, cell]")
            out[ins[1]][_int(ins[2], f"{at}[2]", outputs[ins[1]])] = operand(ins[3], f"{at}[3]")
        elif op in _OPS:
            if len(ins) != 2 + _ARITY[op]:
                raise InputError(f"{at}: {op} takes {_ARITY[op]} operand(s)")
            args = [operand(v, f"{at}[{j + 2}]") for j, v in enumerate(ins[2:])]
            fn = ca.SX.unary if _ARITY[op] == 1 else ca.SX.binary
            cells[_int(ins[1], f"{at}[1]", n_work)] = fn(_OPS[op], *args)
        else:
            raise InputError(f"{at}[0]: unknown operation {op!r}")
    return ca.Function(
        name,
        list(symbols.values()),
        [ca.vertcat(*v) for v in out.values()],
        list(symbols),
        list(out),
    )

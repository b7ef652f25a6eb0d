"""Command lines of the node console scripts: ``--help``, and checks made before rclpy sees the arguments.

A node script takes no options of its own, only ROS arguments after ``--ros-args``. :func:`check_node_arguments`
refuses, with one line each, what rcl would answer with a traceback or silently ignore:

- a trailing ``-p``/``-r``/``--params-file`` (no value), a ``-p`` or ``-r`` value without ``:=``;
- a ``--params-file`` that is missing, unreadable, not YAML or not a mapping of node names;
- any argument outside ``--ros-args`` (e.g. ``helireach_monitor -p x:=1``, whose ``-p`` rclpy would drop).

``-h``/``--help`` (outside ``--ros-args``) prints :func:`node_usage`: the node's name, its parameters
with type, range, default and description, ROS-argument examples and the exit codes. The parameters are
read from the node class's source (its :func:`~helireach_ros.ros.parameters.declare_checked_parameter`
calls), so the text needs no rclpy context and cannot drift from the declarations.
"""

from __future__ import annotations

import ast
import inspect
import math
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from helireach_ros import __version__
from helireach_ros.ros.parameter_table import ParameterSpec, table_specs

__all__ = [
    "HELP_FLAGS",
    "CommandLineError",
    "ParameterSpec",
    "check_node_arguments",
    "check_ros_arguments",
    "node_name_of",
    "node_usage",
    "parameter_specs",
    "wants_help",
]

HELP_FLAGS = ("-h", "--help")
_VALUE_OPTIONS = ("-p", "--param", "-r", "--remap", "--params-file", "--log-level", "--log-config-file", "-e",
                  "--enclave")  # fmt: skip
_RULE_OPTIONS = ("-p", "--param", "-r", "--remap")  # their value is NAME:=VALUE
_DECLARE_FUNCTIONS = ("declare", "declare_checked_parameter")  # the partial every node binds, and the function


class CommandLineError(ValueError):
    """A node command line that cannot be used; the message is one line for stderr."""


def _split(args: Sequence[str]) -> tuple[list[str], list[str]]:
    """(non-ROS arguments, ROS arguments) of ``args`` without the program name; ``--`` ends a ROS section."""
    plain: list[str] = []
    ros: list[str] = []
    in_ros = False
    for argument in args[1:]:
        if argument == "--ros-args":
            in_ros = True
        elif argument == "--" and in_ros:
            in_ros = False
        else:
            (ros if in_ros else plain).append(argument)
    return plain, ros


def wants_help(args: Sequence[str]) -> bool:
    """Whether ``args`` (``sys.argv`` style, program name first) ask for help outside ``--ros-args``."""
    return any(argument in HELP_FLAGS for argument in _split(args)[0])


def _is_parameter_tree(document: Any) -> bool:
    """rcl's layout: node (or namespace) names down to ``ros__parameters`` mappings, e.g. ``/**:`` or
    ``/ns: {node: {ros__parameters: ...}}``."""
    if not isinstance(document, dict) or not document:
        return False
    return all(
        isinstance(section, dict) and (isinstance(section.get("ros__parameters"), dict) or _is_parameter_tree(section))
        for section in document.values()
    )


def _check_params_file(path_text: str) -> None:
    path = Path(path_text).expanduser()
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as error:
        raise CommandLineError(f"--params-file {path_text}: {error.strerror or error}") from None
    except yaml.YAMLError as error:
        where = getattr(error, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        raise CommandLineError(f"--params-file {path_text}: not valid YAML{line}") from None
    if not _is_parameter_tree(document):
        raise CommandLineError(
            f"--params-file {path_text}: expected a mapping of node names to {{ros__parameters: {{...}}}}"
        )


def check_ros_arguments(ros_args: Sequence[str]) -> None:
    """Checks ROS arguments (what follows ``--ros-args``) for the slips rcl reports with a traceback.

    Raises:
        CommandLineError: naming the argument.
    """
    index = 0
    while index < len(ros_args):
        option = ros_args[index]
        if option in _VALUE_OPTIONS:
            if index + 1 >= len(ros_args) or ros_args[index + 1] in ("--ros-args", "--"):
                raise CommandLineError(f"{option} needs a value (e.g. -p stale_timeout:=0.5)")
            value = ros_args[index + 1]
            if option in _RULE_OPTIONS and ":=" not in value:
                raise CommandLineError(f"{option} {value}: expected NAME:=VALUE")
            if option == "--params-file":
                _check_params_file(value)
            index += 2
        else:
            index += 1


def check_node_arguments(args: Sequence[str]) -> None:
    """Checks a node script's command line (``sys.argv`` style): no own options, well-formed ROS arguments.

    Raises:
        CommandLineError: naming the first bad argument.
    """
    plain, ros = _split(args)
    if plain:
        raise CommandLineError(
            f"unexpected argument {plain[0]!r}: node options go after --ros-args (e.g. --ros-args -p name:=value); "
            "see --help"
        )
    check_ros_arguments(ros)


def _type_label(default: Any) -> str:
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, int):
        return "int"
    if isinstance(default, float):
        return "float"
    if isinstance(default, str):
        return "string"
    return "string array" if isinstance(default, list | tuple) else "value"


def _is_declare_call(node: ast.AST) -> bool:
    return isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")).startswith("declare")


def _evaluator(function_node: ast.AST, namespace: dict[str, Any]) -> Any:
    """Evaluates expressions of a function body in its module's namespace plus the simple local constants
    assigned before its last declaration (``defaults = StateLimits()``); whatever needs ``self``, a
    declared value or anything else unavailable stays source text."""
    last_declaration = max(
        (getattr(node, "lineno", 0) for node in ast.walk(function_node) if _is_declare_call(node)), default=0
    )
    local: dict[str, Any] = {}
    for statement in sorted(
        (node for node in ast.walk(function_node) if isinstance(node, ast.Assign)), key=lambda node: node.lineno
    ):
        if (
            statement.lineno < last_declaration
            and len(statement.targets) == 1
            and isinstance(statement.targets[0], ast.Name)
            and not any(isinstance(name, ast.Name) and name.id == "self" for name in ast.walk(statement.value))
            and not any(_is_declare_call(node) for node in ast.walk(statement.value))
        ):
            value = _evaluate(statement.value, namespace, local)
            if not isinstance(value, _SourceText):
                local[statement.targets[0].id] = value
    return lambda expression: _evaluate(expression, namespace, local)


def _evaluate(expression: ast.expr, namespace: dict[str, Any], local: dict[str, Any]) -> Any:
    try:  # our own module's source, for the help text only
        return eval(compile(ast.Expression(expression), "<help>", "eval"), namespace, dict(local))
    except Exception:
        return _SourceText(ast.unparse(expression))


@dataclass(frozen=True)
class _SourceText:
    text: str

    def __repr__(self) -> str:
        return self.text


def _specs_in(function: Any) -> list[ParameterSpec]:
    source = textwrap.dedent(inspect.getsource(function))
    tree = ast.parse(source)
    namespace = vars(inspect.getmodule(function))
    evaluate = _evaluator(tree, namespace)
    specs: list[ParameterSpec] = []
    calls = sorted(
        (node for node in ast.walk(tree) if isinstance(node, ast.Call)), key=lambda n: (n.lineno, n.col_offset)
    )
    for call in calls:
        name = call.func.id if isinstance(call.func, ast.Name) else getattr(call.func, "attr", "")
        arguments = list(call.args)
        if name == "declare_checked_parameter":
            arguments = arguments[1:]  # the node
        if name in _DECLARE_FUNCTIONS and arguments and isinstance(arguments[0], ast.Constant):
            keywords = {keyword.arg: keyword.value for keyword in call.keywords}
            fields = ["name", "default", "description", "value_range", "read_only"]
            given = dict(zip(fields, arguments, strict=False)) | {k: v for k, v in keywords.items() if k in fields}
            values = {key: evaluate(expression) for key, expression in given.items()}
            specs.append(ParameterSpec(**values))
        elif name == "declare_parameters" and len(arguments) == 2:  # a parameter table: its fields
            specs += table_specs(evaluate(arguments[1]))
        elif name.startswith("declare_") and callable(namespace.get(name)):  # e.g. declare_aircraft(self)
            specs += _specs_in(namespace[name])
    return specs


def parameter_specs(node_class: Callable[..., Any]) -> list[ParameterSpec]:
    """The parameters ``node_class.__init__`` declares, in source order (see the module docstring)."""
    return _specs_in(getattr(node_class, "__init__"))  # noqa: B009  # the class's, not an instance's


def node_name_of(node_class: Callable[..., Any]) -> str:
    """The node name ``node_class.__init__`` passes to ``super().__init__`` (the class name if none is found)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(getattr(node_class, "__init__"))))  # noqa: B009
    for call in ast.walk(tree):
        if (
            isinstance(call, ast.Call)
            and getattr(call.func, "attr", "") == "__init__"
            and call.args
            and isinstance(call.args[0], ast.Constant)
            and isinstance(call.args[0].value, str)
        ):
            return call.args[0].value
    return node_class.__name__


def _format_bound(bound: Any) -> str:
    return f"{bound:g}" if isinstance(bound, float) else str(bound)


def _format_value(value: Any) -> str:
    if isinstance(value, float) and math.isnan(value):
        return "NaN"
    if isinstance(value, list | tuple) and len(value) > 3:
        return f"[{len(value)} entries: {value[0]!r}, ...]"
    return repr(value)


def node_usage(script: str, node_name: str, node_class: Callable[..., Any]) -> str:
    """The ``--help`` text of a node console script."""
    summary = (inspect.getdoc(node_class) or "").split("\n\n")[0].replace("\n", " ")
    specs = parameter_specs(node_class)
    lines = [
        f"usage: {script} [-h] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE ...] [-r FROM:=TO ...]]",
        "",
        f"ROS 2 node '{node_name}' (helireach_ros {__version__}). {summary}",
        "",
        "parameters (defaults of the code; helireach bringup loads config/nodes.yaml first; read-only unless "
        "marked 'settable'):",
    ]
    for spec in specs:
        kind = _type_label(spec.default)
        if isinstance(spec.value_range, tuple) and len(spec.value_range) == 2:
            kind += f" in [{_format_bound(spec.value_range[0])}, {_format_bound(spec.value_range[1])}]"
            kind += " or NaN" if isinstance(spec.default, float) and math.isnan(spec.default) else ""
        elif spec.value_range is not None:  # not a literal: its source text
            kind += f" in {spec.value_range!r}"
        settable = ", settable" if spec.read_only is False else ""
        lines.append(f"  {spec.name} ({kind}, default {_format_value(spec.default)}{settable})")
        lines.append(f"      {spec.description}")
    example = next((spec for spec in specs if isinstance(spec.value_range, tuple)), None)
    lines += ["", "examples:"]
    if example is not None:
        lines.append(f"  {script} --ros-args -p {example.name}:={_format_value(example.default)}")
    lines += [
        f"  {script} --ros-args --params-file my_params.yaml   # keys /**/{node_name}: ros__parameters: ...",
        f"  {script} --ros-args -r __ns:=/aircraft1 --log-level debug",
        "",
        "exit codes: 0 stopped by Ctrl-C or SIGTERM (or --help); 2 bad command line, parameter file or parameter "
        "value (one line on stderr)",
    ]
    return "\n".join(lines)

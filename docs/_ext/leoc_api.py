"""Sphinx extension: leoc's API reference pages and its two build-failing checks.

1. **Pages.** For every package in ``leoc_api_packages`` it writes ``api/<package>.rst`` before
   Sphinx reads the sources. The public names of a package are its ``__all__``; a package without
   ``__all__`` (``leoc.evaluation``, ``leoc.experiments``) is documented module by module, each
   module's public names being its ``__all__`` or else the classes and functions it defines (not
   those it imports) whose names do not start with an underscore. Every public name is documented
   where users import it from (``leoc.control.design_lqr``, not ``leoc.control.lqr.design_lqr``).
2. **Missing docstrings.** A public class or function without a docstring of its own, a public
   method or property of such a class without one (inherited docstrings count: ``forward``
   overriding ``torch.nn.Module.forward`` is documented by its base), or a constant in an
   ``__all__`` without a ``#:`` doc comment where it is assigned, is a warning, so that
   ``sphinx-build -W`` fails on it. :func:`missing_docstrings` is the same check as a function
   (``tests/test_docs.py`` runs it without building the site).
3. **Cross-references by defining module.** Docstrings may name an object by the module that
   defines it (``leoc.systems.base.System``) or, inside that module, by its bare name. A reference
   that Sphinx does not resolve is looked up by importing it; when it is the same object as a
   documented public name it is linked there. Anything else stays unresolved and, in nitpicky
   mode, fails the build.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.pycode import ModuleAnalyzer
from sphinx.util import logging

LOGGER = logging.getLogger(__name__)
#: The packages whose public names the API reference documents and the docstring check covers.
PUBLIC_PACKAGES = (
    "leoc.control",
    "leoc.policies",
    "leoc.systems",
    "leoc.pilco",
    "leoc.sb3",
    "leoc.evaluation",
    "leoc.experiments",
    "leoc.deploy",
)
API_DIR = "api"
WARNING_TYPE = "leoc"


@dataclass
class PublicName:
    """One documented name: where users import it from, and the object."""

    module: str  # the public module path, e.g. "leoc.control"
    name: str
    obj: Any

    @property
    def path(self) -> str:
        """Dotted path under which the name is documented."""
        return f"{self.module}.{self.name}"

    @property
    def kind(self) -> str:
        """``class``, ``function`` or ``data``."""
        if inspect.isclass(self.obj):
            return "class"
        if inspect.isfunction(self.obj) or inspect.isbuiltin(self.obj):
            return "function"
        return "data"


@dataclass
class ModuleSection:
    """One module's part of a package page."""

    module: ModuleType
    names: list[PublicName] = field(default_factory=list)


def _defined_here(module: ModuleType, value: Any) -> bool:
    return getattr(value, "__module__", None) == module.__name__


def module_public_names(module: ModuleType) -> list[PublicName]:
    """The public names of ``module``: its ``__all__``, or the classes and functions it defines."""
    if hasattr(module, "__all__"):
        names = list(module.__all__)
    else:
        names = [
            name
            for name, value in vars(module).items()
            if not name.startswith("_")
            and (inspect.isclass(value) or inspect.isfunction(value))
            and _defined_here(module, value)
        ]
    return [PublicName(module.__name__, name, getattr(module, name)) for name in names]


def package_sections(package_name: str) -> list[ModuleSection]:
    """The modules documented for a package: itself if it has ``__all__``, else each submodule."""
    package = importlib.import_module(package_name)
    if hasattr(package, "__all__") or not hasattr(package, "__path__"):
        return [ModuleSection(package, module_public_names(package))]
    sections = []
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda item: item.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{package_name}.{info.name}")
        sections.append(ModuleSection(module, module_public_names(module)))
    return sections


def _defining_module(public: PublicName) -> str | None:
    """Where a constant is assigned: the public module or one of its submodules."""
    candidates = [public.module]
    package = sys.modules[public.module]
    if hasattr(package, "__path__"):
        submodules = pkgutil.iter_modules(package.__path__)
        candidates += [f"{public.module}.{info.name}" for info in submodules]
    # re-exported from another leoc module (``Controller`` of ``leoc.systems.rollout``)
    candidates += [
        name
        for name, module in sorted(sys.modules.items())
        if name.startswith("leoc") and getattr(module, public.name, None) is public.obj
    ]
    for candidate in candidates:
        try:
            analyzer = ModuleAnalyzer.for_module(candidate)
            analyzer.analyze()
        except Exception:  # noqa: BLE001 - a module without source simply does not qualify
            continue
        if ("", public.name) in analyzer.attr_docs:
            return candidate
    return None


def constant_doc(public: PublicName) -> list[str] | None:
    """The ``#:`` doc comment of a constant where it is assigned, or None."""
    where = _defining_module(public)
    if where is None:
        return None
    analyzer = ModuleAnalyzer.for_module(where)
    return list(analyzer.attr_docs[("", public.name)])


def _own_doc(obj: Any) -> str:
    return (obj.__doc__ or "").strip() if "__doc__" in vars(obj) or not inspect.isclass(obj) else ""


def _inherited_doc(klass: type, member_name: str) -> str:
    """The docstring of ``klass.member_name`` or of the same name on a base class."""
    for base in klass.__mro__:
        member = vars(base).get(member_name)
        if member is None:
            continue
        target = getattr(member, "fget", None) or getattr(member, "__func__", member)
        doc = (getattr(target, "__doc__", None) or "").strip()
        if doc:
            return doc
    return ""


def _member_problems(public: PublicName) -> list[str]:
    problems = []
    for member_name, member in vars(public.obj).items():
        if member_name.startswith("_"):
            continue
        target = getattr(member, "__func__", member)
        if not (isinstance(member, property) or inspect.isfunction(target)):
            continue
        if not _inherited_doc(public.obj, member_name):
            kind = "property" if isinstance(member, property) else "method"
            problems.append(f"{public.path}.{member_name}: public {kind} without a docstring")
    return problems


def missing_docstrings(packages: list[str]) -> list[str]:
    """Every public name of ``packages`` that has no docstring, one line each (empty: all good)."""
    problems = []
    for package in packages:
        for section in package_sections(package):
            for public in section.names:
                if public.kind == "data":
                    if constant_doc(public) is None:
                        problems.append(
                            f"{public.path}: public constant without a '#:' doc comment"
                        )
                    continue
                if not _own_doc(public.obj):
                    problems.append(f"{public.path}: public {public.kind} without a docstring")
                if public.kind == "class":
                    problems.extend(_member_problems(public))
    return problems


def _heading(text: str, underline: str) -> list[str]:
    return [text, underline * len(text), ""]


def _directives(public: PublicName) -> list[str]:
    if public.kind == "class":
        return [
            f".. autoclass:: {public.path}",
            "   :members:",
            "   :show-inheritance:",
            "",
        ]
    if public.kind == "function":
        return [f".. autofunction:: {public.path}", ""]
    lines = [f".. py:data:: {public.path}", f"   :value: {public.obj!r}"[:200], ""]
    lines += ["   " + line if line else "" for line in (constant_doc(public) or [])]
    return lines + [""]


KIND_TITLES = (("class", "Classes"), ("function", "Functions"), ("data", "Constants"))


def _grouped(names: list[PublicName], level: str) -> list[str]:
    lines: list[str] = []
    for kind, title in KIND_TITLES:
        group = [public for public in names if public.kind == kind]
        if not group:
            continue
        lines += _heading(title, level)
        for public in group:
            lines += _directives(public)
    return lines


def _automodule(module: str, exclude: list[str]) -> list[str]:
    lines = [
        f".. automodule:: {module}",
        "   :members:",
        "   :undoc-members:",
        "   :ignore-module-all:",
    ]
    lines.append("   :show-inheritance:")
    if exclude:
        lines.append(f"   :exclude-members: {', '.join(sorted(exclude))}")
    return lines + [""]


def _submodules(package: ModuleType) -> list[ModuleType]:
    if not hasattr(package, "__path__"):
        return []
    return [
        importlib.import_module(f"{package.__name__}.{info.name}")
        for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda item: item.name)
        if not info.name.startswith("_")
    ]


def package_page(package_name: str) -> str:
    """The reStructuredText of one package's API page.

    A package with ``__all__``: its public names grouped by kind, then each submodule's other
    documented names (what the public ones return or mention). A package without: one section
    per submodule with its members (its ``__all__``, or every documented name it defines).
    """
    package = importlib.import_module(package_name)
    lines = [f".. Generated by docs/_ext/leoc_api.py from {package_name}; do not edit.", ""]
    lines += _heading(f"``{package_name}``", "=")
    if not hasattr(package, "__path__"):  # a plain module: everything it documents
        return "\n".join(lines + _automodule(package_name, [])) + "\n"
    lines += [f".. automodule:: {package_name}", "   :no-members:", ""]
    lines += [f".. currentmodule:: {package_name}", ""]
    if hasattr(package, "__all__"):
        public = module_public_names(package)
        lines += _grouped(public, "-")
        exported = {id(item.obj) for item in public}
        submodules = _submodules(package)
        if submodules:
            lines += _heading("Submodules", "-")
            lines += [
                "Documented names of the modules behind the package that it does not export.",
                "",
            ]
        for module in submodules:
            exclude = [name for name, value in vars(module).items() if id(value) in exported]
            lines += _heading(f"``{module.__name__}``", "~")
            lines += _automodule(module.__name__, exclude)
        return "\n".join(lines) + "\n"
    for module in _submodules(package):
        lines += _heading(f"``{module.__name__}``", "-")
        lines += _automodule(module.__name__, [])
    return "\n".join(lines) + "\n"


def write_pages(app: Sphinx) -> None:
    """Write the API pages and report every public name without a docstring."""
    out_dir = Path(app.srcdir) / API_DIR / "generated"
    out_dir.mkdir(parents=True, exist_ok=True)
    packages = list(app.config.leoc_api_packages) + list(app.config.leoc_api_extra_modules)
    for package in packages:
        page = out_dir / f"{package}.rst"
        text = package_page(package)
        if not page.exists() or page.read_text() != text:  # unchanged pages stay unchanged
            page.write_text(text)
    for stale in set(out_dir.glob("*.rst")) - {out_dir / f"{name}.rst" for name in packages}:
        stale.unlink()  # the page of a package that moved or went
    if app.config.leoc_api_check_docstrings:
        for problem in missing_docstrings(list(app.config.leoc_api_packages)):
            LOGGER.warning(problem, type=WARNING_TYPE, subtype="docstring")


def _documented_paths(app: Sphinx) -> dict[int, str]:
    """Object id -> the path it is documented under (classes, functions and modules)."""
    cache = getattr(app.env, "_leoc_documented", None)
    if cache is not None:
        return cache
    documented: dict[int, str] = {}
    objects = app.env.get_domain("py").objects
    for path in objects:
        obj = _import_path(path)
        if _linkable(obj):
            documented.setdefault(id(obj), path)
    app.env._leoc_documented = documented
    return documented


def _linkable(obj: Any) -> bool:
    # only objects with a stable identity: small ints or interned strings would alias
    return (
        inspect.isclass(obj)
        or inspect.isfunction(obj)
        or inspect.ismodule(obj)
        or isinstance(obj, property)
    )


def _import_path(path: str) -> Any:
    parts = path.split(".")
    for split in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:split]))
        except ImportError:
            continue
        try:
            for attribute in parts[split:]:
                obj = getattr(obj, attribute)
        except AttributeError:
            return None
        return obj
    return None


def _candidates(target: str, node: Any) -> list[str]:
    target = target.lstrip("~.")
    module = node.get("py:module")
    klass = node.get("py:class")
    candidates = [target]
    if module:
        if klass:
            candidates.append(f"{module}.{klass}.{target}")
        candidates.append(f"{module}.{target}")
    return candidates


def _unique_suffix_match(env: Any, target: str) -> str | None:
    """The one documented leoc object whose path ends with ``.target``, if exactly one."""
    suffix = "." + target.lstrip("~.")
    matches = {
        path
        for path in env.get_domain("py").objects
        if path.startswith("leoc") and path.endswith(suffix)
    }
    if len(matches) == 1:
        return matches.pop()
    objects = [_import_path(path) for path in matches]
    if matches and all(_linkable(obj) and obj is objects[0] for obj in objects):
        return min(matches, key=len)  # one object documented under two paths
    return None


def _resolved_path(app: Sphinx, env: Any, node: Any) -> str | None:
    target = node.get("reftarget", "")
    documented = _documented_paths(app)
    for candidate in _candidates(target, node):
        if not candidate.startswith("leoc"):
            continue
        obj = _import_path(candidate)
        path = documented.get(id(obj)) if obj is not None and _linkable(obj) else None
        if path is not None:
            return path
    # a bare name used inside the module that defines it, rendered under the package's path
    path = _unique_suffix_match(env, target)
    if path is not None or "." not in target:
        return path
    # a NamedTuple field (its accessor is not documented on its own): link to the class
    owner, field_name = target.rsplit(".", 1)
    owner_node = {"py:module": node.get("py:module"), "py:class": node.get("py:class")}
    owner_node["reftarget"] = owner
    owner_path = _resolved_path(app, env, owner_node)
    owner_obj = _import_path(owner_path) if owner_path else None
    if owner_obj is not None and field_name in getattr(owner_obj, "_fields", ()):
        return owner_path
    return None


def resolve_by_object(app: Sphinx, env: Any, node: Any, contnode: Any) -> Any:
    """Link a reference by the module that defines it to the public name's documentation."""
    if node.get("refdomain") != "py":
        return None
    path = _resolved_path(app, env, node)
    if path is not None:
        found = env.get_domain("py").objects[path]
        reference = nodes.reference("", "", internal=True, reftitle=path)
        reference["refuri"] = app.builder.get_relative_uri(node["refdoc"], found.docname)
        reference["refuri"] += "#" + found.node_id
        reference.append(contnode)
        return reference
    return None


def skip_namedtuple_fields(app: Sphinx, what: str, name: str, obj: Any, skip: bool, options: Any):
    """Leave out a NamedTuple's field accessors ("Alias for field number N"): the class's
    Attributes section already documents every field, with its meaning."""
    if (getattr(obj, "__doc__", None) or "").startswith("Alias for field number"):
        return True
    return None


def setup(app: Sphinx) -> dict[str, Any]:
    """Register the configuration values and the event handlers."""
    app.add_config_value("leoc_api_packages", list(PUBLIC_PACKAGES), "env")
    app.add_config_value("leoc_api_extra_modules", [], "env")
    app.add_config_value("leoc_api_check_docstrings", True, "env")
    app.connect("builder-inited", write_pages)
    app.connect("missing-reference", resolve_by_object)
    app.connect("autodoc-skip-member", skip_namedtuple_fields)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}

"""The one contract every estimator keeps (scikit-learn's): settings in, ``fit``, results ending in ``_``.

Settings are the constructor's parameters, stored under their own names and
never changed by ``fit``: ``get_params()`` reads them back through the
constructor's signature, so ``clone()`` is an unfitted twin and a fitted
estimator still says how it was set up; ``set_params()`` changes them between
fits, by name. Results exist only after a fit that succeeded: a fit that raises
(bad data, a budget, Ctrl-C) leaves the results as they were before it, so a
failed fit never reads as fitted. A result asked for before ``fit`` raises
``NotFittedError`` with what to do, not a bare AttributeError.
"""

from __future__ import annotations

import copy
import functools
import inspect
from collections.abc import Callable
from typing import Any, Protocol, Self, runtime_checkable

from ..errors import InputError, NotFittedError


@runtime_checkable
class Estimator(Protocol):
    """What the rest of tankdaq may rely on: settings readable and copyable, a fit that returns self."""

    def fit(self, *args: Any, **kwargs: Any) -> Self: ...

    def get_params(self) -> dict[str, Any]: ...

    def clone(self) -> Self: ...


def _is_result(name: str) -> bool:
    return name.endswith("_") and not name.startswith("_")


def _results_only_on_success(fit: Callable[..., Any]) -> Callable[..., Any]:
    """``fit`` such that, when it raises, the estimator's results are those it had before the call."""

    @functools.wraps(fit)
    def guarded(self: Any, *args: Any, **kwargs: Any) -> Any:
        before = {name: value for name, value in self.__dict__.items() if _is_result(name)}
        try:
            return fit(self, *args, **kwargs)
        except BaseException:
            for name in [name for name in self.__dict__ if _is_result(name)]:
                del self.__dict__[name]
            self.__dict__.update(before)
            raise

    guarded.__dict__["_guards_results"] = True
    return guarded


class EstimatorMixin:
    """``get_params``, ``set_params``, ``clone`` and the not-fitted check, shared by every estimator.

    A subclass's own ``fit`` is wrapped so that its results appear only when it returns.
    """

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        fit = cls.__dict__.get("fit")
        if callable(fit) and not getattr(fit, "_guards_results", False):
            cls.fit = _results_only_on_success(fit)  # type: ignore[attr-defined]

    def get_params(self) -> dict[str, Any]:
        """The constructor's settings by name, as given (read through the constructor's signature).

        Settings taken as ``**kwargs`` are kept as a dict under that parameter's name and come back
        flattened, as they were passed.
        """
        params: dict[str, Any] = {}
        if type(self).__init__ is object.__init__:
            return params  # no settings at all
        for name, parameter in inspect.signature(type(self).__init__).parameters.items():
            if name == "self" or parameter.kind is inspect.Parameter.VAR_POSITIONAL:
                continue
            if parameter.kind is inspect.Parameter.VAR_KEYWORD:
                params.update(self.__dict__[name])
            else:
                params[name] = self.__dict__[name]
        return params

    def set_params(self, **params: Any) -> Self:
        """Change settings by name (between fits); a name the constructor does not take is refused."""
        own = type(self).__init__ is not object.__init__
        signature = inspect.signature(type(self).__init__).parameters if own else {}
        keywords = next((n for n, p in signature.items() if p.kind is inspect.Parameter.VAR_KEYWORD), None)
        named = {
            n for n, p in signature.items() if n != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD
        }
        for name in params:
            if name not in named and keywords is None:
                listed = ", ".join(sorted(named)) or "none"
                raise InputError(f"{type(self).__name__} has no setting {name!r}: its settings are {listed}")
        for name, value in params.items():
            if name in named:
                setattr(self, name, value)
            else:  # taken by the constructor's **settings, as it would be
                self.__dict__[str(keywords)][name] = value
        return self

    def clone(self, **changes: Any) -> Self:
        """An unfitted estimator with the same settings but ``changes`` (containers copied, not shared)."""
        params = {
            name: copy.deepcopy(value) if isinstance(value, list | dict | set) else value
            for name, value in self.get_params().items()
        }
        return type(self)(**(params | changes))

    @property
    def fitted(self) -> bool:
        """Whether ``fit`` has made results (attributes ending in ``_``)."""
        return any(k.endswith("_") and not k.startswith("_") for k in self.__dict__)

    def check_fitted(self) -> None:
        """Raise ``NotFittedError`` unless ``fit`` has run."""
        if not self.fitted:
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet: call fit(...) first")

    def __getattr__(self, name: str) -> Any:
        # only reached when normal lookup fails: a result asked for too early gets a clear error
        if name.endswith("_") and not name.startswith("_") and not self.fitted:
            raise NotFittedError(f"{type(self).__name__}.{name} is a result: call fit(...) first")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

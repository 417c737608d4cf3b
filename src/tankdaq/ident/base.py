"""The one contract every estimator keeps (scikit-learn's): settings in, ``fit``, results ending in ``_``.

Settings are the constructor's parameters, stored under their own names and
never changed by ``fit``: ``get_params()`` reads them back through the
constructor's signature, so ``clone()`` is an unfitted twin and a fitted
estimator still says how it was set up. A result asked for before ``fit``
raises ``NotFittedError`` with what to do, not a bare AttributeError.
"""

from __future__ import annotations

import copy
import inspect
from typing import Any, Protocol, Self, runtime_checkable

from ..errors import NotFittedError


@runtime_checkable
class Estimator(Protocol):
    """What the rest of tankdaq may rely on: settings readable and copyable, a fit that returns self."""

    def fit(self, *args: Any, **kwargs: Any) -> Self: ...

    def get_params(self) -> dict[str, Any]: ...

    def clone(self) -> Self: ...


class EstimatorMixin:
    """``get_params``, ``clone`` and the not-fitted check, shared by every estimator."""

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

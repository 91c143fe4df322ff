"""ARIMA with the weather as exogenous regressors (regression with ARIMA errors).

Order selection: every (p, d, q) of a small grid is fitted by maximum likelihood
(statsmodels SARIMAX, L-BFGS, at most `maxiter` iterations) on the last `fit_samples`
points of the training part, in min-max-scaled units; the converged fit with the
lowest AIC wins (if none converged: the lowest AIC, with `converged` False). Forecasting: the fitted
parameters are frozen and the Kalman filter runs over the given history
(`results.apply(..., refit=False)`); its one-step-ahead prediction for t uses the
observations before t and the weather at t. No refit on the test part.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import numpy as np

from opfbench.errors import DataError
from opfbench.forecasting.base import Forecaster
from opfbench.forecasting.scaling import MinMaxScaler

Order = tuple[int, int, int]


def order_grid(max_p: int = 2, max_d: int = 1, max_q: int = 2) -> tuple[Order, ...]:
    """All (p, d, q) with p <= max_p, d <= max_d, q <= max_q."""
    return tuple(itertools.product(range(max_p + 1), range(max_d + 1), range(max_q + 1)))


@dataclass(frozen=True)
class OrderFit:
    """One candidate of the order search: AIC (inf when the fit failed) and convergence."""

    order: Order
    aic: float
    converged: bool


class Arima(Forecaster):
    """ARIMA(p, d, q) errors + linear weather regression, order by AIC.

    Args:
        orders: candidate (p, d, q) orders; a constant is included when d = 0.
        fit_samples: number of most recent training points used for fitting.
        warmup_samples: history length the Kalman filter should see before the first
            wanted forecast (the state starts from its stationary / diffuse prior).
        use_exog: include the weather regressors (ARIMAX); False gives plain ARIMA.
        maxiter: iteration limit of each likelihood maximisation.
    """

    name = "arima"

    def __init__(
        self,
        orders: tuple[Order, ...] = order_grid(),
        fit_samples: int = 5000,
        warmup_samples: int = 2000,
        use_exog: bool = True,
        maxiter: int = 200,
    ) -> None:
        super().__init__()
        self.orders = orders
        self.fit_samples = fit_samples
        self.warmup_samples = warmup_samples
        self.use_exog = use_exog
        self.maxiter = maxiter
        self.search: list[OrderFit] = []
        self.order: Order | None = None
        self.converged = False
        _convergence_warning()  # import statsmodels when the model is built, not inside the timed fit

    @property
    def lookback(self) -> int:
        return 1

    @property
    def warmup(self) -> int:
        return self.warmup_samples

    def _fit(self, y: np.ndarray, x: np.ndarray) -> None:
        self._y_scaler = MinMaxScaler.fit(y)
        self._x_scaler = MinMaxScaler.fit(x)
        ys = self._y_scaler.transform(y[-self.fit_samples :])
        xs = self._exog(x[-self.fit_samples :])
        results = {}
        self.search = []
        for order in self.orders:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", _convergence_warning())
                    warnings.simplefilter("ignore", UserWarning)
                    result = _model(ys, xs, order).fit(disp=False, maxiter=self.maxiter)
            except (np.linalg.LinAlgError, ValueError):
                self.search.append(OrderFit(order, float("inf"), False))
                continue
            aic = float(result.aic) if np.isfinite(result.aic) else float("inf")
            self.search.append(OrderFit(order, aic, bool(result.mle_retvals.get("converged", False))))
            results[order] = result
        candidates = [f for f in self.search if f.order in results and np.isfinite(f.aic)]
        if not candidates:
            raise DataError(f"arima: no candidate order could be fitted ({len(self.orders)} tried)")
        best = min(candidates, key=lambda f: (not f.converged, f.aic))
        self.order, self.converged, self._result = best.order, best.converged, results[best.order]

    def _predict(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        ys = self._y_scaler.transform(y)
        applied = self._result.apply(ys, exog=self._exog(x), refit=False)
        one_step = np.asarray(applied.predict(), dtype=float)
        return self._y_scaler.inverse(one_step[self.lookback :])

    def _exog(self, x: np.ndarray) -> np.ndarray | None:
        return self._x_scaler.transform(x) if self.use_exog else None


def _convergence_warning() -> type[Warning]:
    from statsmodels.tools.sm_exceptions import ConvergenceWarning  # statsmodels only when fitting

    return ConvergenceWarning


def _model(y: np.ndarray, x: np.ndarray | None, order: Order):
    from statsmodels.tsa.statespace.sarimax import SARIMAX  # statsmodels only when fitting

    return SARIMAX(y, exog=x, order=order, trend="c" if order[1] == 0 else "n")

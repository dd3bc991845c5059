"""Wall-clock timing of calls: the best of several, in interleaved rounds.

Machines are noisy, and a shared one drifts in load: timing contenders in rounds that call each
once in turn (A, B, C, A, B, C, ...) exposes them all to the same drifts, and the best time of
each is the one least disturbed.
"""

import time

import numpy as np


def best_time(function, *args, repeats=3):
    """Smallest wall time of ``repeats`` calls of ``function(*args)``, and the last result."""
    best = np.inf
    result = None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function(*args)
        best = min(best, time.perf_counter() - start)
    return best, result


def interleaved_best_times(calls, rounds=5):
    """Best wall time of each call over ``rounds`` interleaved rounds.

    Parameters
    ----------
    calls : dict of str -> callable
        Functions of no arguments; each timed region holds one call and nothing else.
    rounds : int

    Returns
    -------
    best : dict of str -> float
        Smallest time of each call, in seconds.
    results : dict of str -> object
        What each call returned in the last round.
    """
    best = dict.fromkeys(calls, np.inf)
    results = {}
    for _ in range(rounds):
        for name, call in calls.items():
            results.pop(name, None)  # the previous result is freed outside the clock
            start = time.perf_counter()
            result = call()
            best[name] = min(best[name], time.perf_counter() - start)
            results[name] = result
    return best, results

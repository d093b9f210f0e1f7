"""Sparse selection of terms by grouped cross-validation: forward steps that
add the candidate which earns its place on held-out poses, then a backward
check that drops any that no longer does.  Plain numpy + scipy.

Each round tries every candidate not yet in the model (the named library and
the dictionary together) and measures (identification/diagnosis/candidate_evaluation.py),
on the same pose-grouped folds:

  * its held-out RMS (all displacement components; every nonlinear parameter
    refitted inside each fold, see identification/diagnosis/terms.py);
  * a grouped test of its parameters on all rows with the covariance
    clustered by pose (cross_validation.clustered_wald), valid whatever the
    correlation of a pose's rows, with the small-sample corrections for few
    poses (CR2 sandwich, a Bell-McCaffrey t per contrast, Bonferroni over
    them; clustered_test.py);
  * for reference, a nested F-test on all rows and the change in BIC (these
    treat rows as independent; the decision does not use them).

A candidate qualifies when its grouped test passes at ALPHA_ROUND divided
by the number of candidates tried in the round (Bonferroni) and it lowers
the held-out RMS by MIN_GAIN of the current value (10 % for a named effect,
5 % for a dictionary term).  The grouped test needs more poses than the
model has parameters (candidate_evaluation); a candidate that would qualify
on its held-out gain and its nested F-test but that the poses are too few
to test is ``undecided``: the verdict says so and what would decide it, and
nothing is named (studies/small_campaigns.py).  The best qualifying named effect is preferred
unless a dictionary term beats its held-out RMS by more than
NAMED_PREFERENCE.  A candidate whose columns the campaign cannot separate
from the model's (rank) is "not identifiable" and never selected; one that
needs a column the file lacks, or more parameters than the data support, is
skipped, with the reason.

A typical size is a prior, not a veto (identification/diagnosis/priors.py): a
candidate beyond its typical range is added only on decisive evidence and
pays a penalty in the choice; one that needs a sign physics forbids, or
that drives a joint's compliance negative that was positive, is never
added.  What fits but is not added is kept as a *lead*, reported with the
reason.  The backward check applies the same rule at the final fit and
never drops a term whose removal would make a compliance negative.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.diagnosis.candidate_evaluation import State, evaluate, implausible_terms, model_state
from robstiff_drake.identification.diagnosis.priors import decisive, final_evidence, refusal, score
from robstiff_drake.identification.diagnosis.cross_validation import clustered_wald, rows_to_eq
from robstiff_drake.progress import progress

ALPHA_ROUND = 0.01
MIN_GAIN = {"library": 0.10, "dictionary": 0.05}
NAMED_PREFERENCE = 0.05
MIN_KEEP_GAIN = 0.02  # backward check: a kept term must still lower the held-out RMS by this much
MAX_LIBRARY = 3
MAX_TERMS = 5


def _fits(r, current_rms, m):
    """The candidate's fit earns a place (held-out gain and clustered test; no clustered p when the poses are too
    few for the model's parameters, candidate_evaluation)."""
    return (r.status == "ok" and r.rms_mm <= (1 - MIN_GAIN[r.source]) * current_rms
            and r.p_grouped < ALPHA_ROUND / max(m, 1))


def undecided(r, current_rms, m):
    """A candidate the campaign has too few poses to test (poses_needed) whose
    held-out gain and nested F-test would let it qualify."""
    return (r.status == "ok" and r.poses_needed > 0 and r.rms_mm <= (1 - MIN_GAIN[r.source]) * current_rms
            and r.p_value < ALPHA_ROUND / max(m, 1))


def _qualifies(r, current_rms, m, floor_mm=None):
    if not _fits(r, current_rms, m) or r.physical is False or r.forbidden:
        return False
    return r.plausible is not False or decisive(r, current_rms, floor_mm)[0]


def leads(r, current_rms, m, floor_mm=None):
    """A candidate that fits but is not added: forbidden by physics, or
    beyond its typical size without decisive evidence."""
    return _fits(r, current_rms, m) and not _qualifies(r, current_rms, m, floor_mm)


def _choose(qualified):
    lib = [r for r in qualified if r.source == "library"]
    dic = [r for r in qualified if r.source == "dictionary"]
    best_lib = min(lib, key=score) if lib else None
    best_dic = min(dic, key=score) if dic else None
    if best_lib and (best_dic is None or score(best_lib) <= (1 + NAMED_PREFERENCE) * score(best_dic)):
        return best_lib
    return best_dic


def _dropped_lead(rounds, name, why, refused=None):
    """(round, result) of a term added in an earlier round and dropped at the final fit (forbidden, or beyond its
    typical size without decisive evidence there)."""
    for i, rnd in enumerate(rounds):
        for r in rnd:
            if r.name == name:
                return i, replace(r, plausible=False, plausibility=why + " (at the final fit; dropped)",
                                  forbidden=pl.forbidden(why), refusal=f"{why}; {refused or ''} (at the final fit; "
                                  "dropped)" if refused else why + " (at the final fit; dropped)")
    raise KeyError(name)


@dataclass
class SearchResult:
    state: State
    rms_before_mm: float
    rounds: list  # per round, the list of CandidateResult
    n_hypotheses: int  # candidates tested (status ok) over all rounds
    added: list  # [(name, held-out RMS before, after)]
    dropped: list  # names dropped by the backward check
    rms_without_mm: dict  # kept term -> held-out RMS of the final model without it
    leads: list = field(default_factory=list)  # [(round index, CandidateResult)]: fits, but not physical/plausible
    rival_trends: list = field(default_factory=list)  # [(term chosen, trend CandidateResult fitting as well)]
    undecided: list = field(default_factory=list)  # CandidateResult that would qualify but the poses are too few


def _forward(ctx, rows, folds, gidx, state, terms_by_name, banned, rounds, added, found, rivals, floor_mm=None,
             small=None):
    """Forward steps from ``state`` until no candidate qualifies; returns the
    state and the number of hypotheses tested."""
    n_tried = 0
    while len(state.terms) < MAX_TERMS:
        names = {t.name for t in state.terms}
        n_lib = sum(t.source == "library" for t in state.terms)
        pool = [t for t in terms_by_name.values() if t.name not in names and t.name not in banned
                and (t.source != "library" or n_lib < MAX_LIBRARY)]
        if not pool:
            break
        need = (1 - min(MIN_GAIN.values())) * state.rms_mm
        # a bar on a terminal (off elsewhere and with --quiet): a round tries every term of the pool
        with progress(len(pool), None, f"diagnosis, round {len(rounds) + 1}", unit="term", leave=False) as bar:
            results = []
            for t in pool:
                results.append(evaluate(ctx, rows, folds, gidx, state, t, need))
                bar.update(1)
        rounds.append(results)
        m = sum(r.status == "ok" for r in results)
        n_tried += m
        for r in results:
            if leads(r, state.rms_mm, m, floor_mm):
                r.refusal = refusal(r, state.rms_mm, floor_mm)
                found.append((len(rounds) - 1, r))
        qualified = [r for r in results if _qualifies(r, state.rms_mm, m, floor_mm)]
        best = _choose(qualified)
        if best is None:
            if small is not None:  # against the model the search ends with, not an earlier round's
                small += [r for r in results if undecided(r, state.rms_mm, m)]
            break
        # a trend along the file's order that fits about as well as the cause chosen, held out: the data cannot
        # tell them apart (the file has no measurement order); said with the verdict.  A rival need not pass the
        # clustered test itself (it names nothing; the trend's columns put their leverage on the first and last
        # poses, where the corrected test is strictest): its held-out gain is enough
        rivals += [(best.name, r) for r in results if r.status == "ok" and terms_by_name[r.name].trend
                   and r.name != best.name and r.physical is not False
                   and r.rms_mm <= (1 - MIN_GAIN[r.source]) * state.rms_mm
                   and r.rms_mm <= (1 + NAMED_PREFERENCE) * best.rms_mm]
        new = model_state(ctx, state.terms + [terms_by_name[best.name]], rows, folds, gidx)
        added.append((best.name, state.rms_mm, new.rms_mm))
        state = new
    return state, n_tried


def _backward(ctx, rows, folds, gidx, state, rounds, dropped, found, floor_mm=None):
    """The backward check (module docstring).  Returns (state, {kept term:
    held-out RMS without it}, names dropped as implausible)."""
    geq = np.repeat(gidx, 3)
    eq = rows_to_eq(rows)
    gone = []
    while state.terms:
        trial = {}
        for t in state.terms:
            s = model_state(ctx, [u for u in state.terms if u is not t], rows, folds, gidx)
            p, _, _ = clustered_wald(state.full.X[eq], ctx.b[eq] - state.full.offset[eq], geq,
                                     state.full.slices[t.name])
            trial[t.name] = (s, p, 1 - state.rms_mm / s.rms_mm)
        implausible, refused = implausible_terms(ctx, state, rows, geq), {}
        for name in list(implausible):  # beyond its typical size: kept on decisive evidence at the final fit
            if pl.forbidden(implausible[name]):
                continue
            ok, why = decisive(final_evidence(ctx, state, trial[name][0], trial[name][1], name, rows, folds),
                               trial[name][0].rms_mm, floor_mm)
            if ok:
                implausible.pop(name)
            else:
                refused[name] = why
        n = len(state.terms)
        weak = [(name not in implausible, gain, name) for name, (s, p, gain) in trial.items()
                if (name in implausible or (n > 1 and (p > ALPHA_ROUND / n or gain < MIN_KEEP_GAIN)))
                and not any(s.full.c[j] <= 0 < state.full.c[j] for j in ctx.free)]
        if not weak:
            return state, {name: s.rms_mm for name, (s, _, _) in trial.items()}, gone
        name = min(weak)[2]
        dropped.append(name)
        if name in implausible:
            found.append(_dropped_lead(rounds, name, implausible[name], refused.get(name)))
            gone.append(name)
        state = trial[name][0]
    return state, {}, gone


MAX_RESTARTS = 3  # forward searches resumed after the backward check dropped an implausible term


def search(ctx, rows, folds, terms_by_name, groups, floor_mm=None):
    """Forward selection over ``terms_by_name`` (library and dictionary), then
    the backward check; when that drops a term as implausible at the final
    fit, the forward search resumes without it.  ``groups`` (N,): the units
    of the clustered tests; ``floor_mm``: the noise floor (None: unknown; then
    no size beyond the typical is kept)."""
    gidx = np.unique(np.asarray(groups)[rows], return_inverse=True)[1]
    state = model_state(ctx, [], rows, folds, gidx)
    rms_before = state.rms_mm
    rounds, added, dropped, found, banned, n_tried, rivals, small = [], [], [], [], set(), 0, [], []
    for _ in range(MAX_RESTARTS + 1):
        state, n = _forward(ctx, rows, folds, gidx, state, terms_by_name, banned, rounds, added, found, rivals,
                            floor_mm, small)
        n_tried += n
        state, without, gone = _backward(ctx, rows, folds, gidx, state, rounds, dropped, found, floor_mm)
        if not gone:
            break
        banned |= set(gone)
    if len(state.terms) == 1:
        without = {state.terms[0].name: rms_before}
    kept = {t.name for t in state.terms}
    dropped = [n for n in dict.fromkeys(dropped) if n not in kept]
    return SearchResult(state, rms_before, rounds, n_tried, added, dropped, without,
                        [(i, r) for i, r in found if r.name not in kept],
                        [(c, r) for c, r in rivals if c in kept and r.name not in kept],
                        sorted([r for r in small if r.name not in kept], key=lambda r: r.p_value))

"""The verdict of a stiffness campaign's diagnosis (identification/diagnosis/campaign_diagnosis.py)
in words: whether the final model explains the data, and, where the data
cannot decide, which measurement would.  Plain Python.

"Not established" is the honest answer when the floor is reached only with
hypotheses found by searching the dictionary, or when something the model
may not carry (a lead of implausible size) fits better.  The text then
names what would decide it: where the term's estimate is confounded with
another effect (identification/diagnosis/confounding.py) the measurements that
separate the two (``robstiff plan-poses N --separate A,B``, planned to add
to the campaign); otherwise a second campaign at other poses, on which the
hypothesis is tested again rather than chosen.
"""

from robstiff_drake.identification.diagnosis import noise_floor as nf
from robstiff_drake.identification.diagnosis import selection

# A stated floor the held-out residual is significantly below (lower tail of
# the lack-of-fit test at this level) is reported as overstated.
ALPHA_FLOOR_ABOVE = 0.01


def verdict(d, floor, lof, non_physical, discovered, setup, structure, n_hyp, leads=(), confounded=()):
    """(explains_data, the verdict's text): True, False or None (no verdict).
    ``setup``: the findings of the kept terms beyond their typical size
    ("name: finding"), said with the verdict."""
    said = f"; setup finding{'s' if len(setup) > 1 else ''}: {'; '.join(setup)}" if setup else ""
    if non_physical:
        head = (f"no verdict: the six springs alone need a negative compliance of joint(s) "
                f"{', '.join(map(str, non_physical))} (non-physical)")
        fix = [r for r in leads if r["all_positive"]]
        if fix:
            return None, (f"{head}; {fix[0]['name']} would make every compliance positive (held-out "
                          f"{fix[0]['rms_mm']:.4f} mm) but was not added: {fix[0]['reason']}: the model lacks "
                          "something that looks like it" + decides([fix[0]["name"]], confounded))
        return None, f"{head}, and nothing the search tried reverses it; check the signs and units of the " \
                     "displacements and forces"
    if floor.sigma_mm is None:
        return None, ("no verdict: no noise floor is known (state it with --noise-mm, or measure replicate rows: "
                      "the same pose and load); whether the model explains the data cannot be said")
    where = ", ".join(f"{s['variable']} ({100 * s['strength']:.0f} %)" for s in structure[:3] if s["strength"] > 0.02)
    above = lof.p_value < nf.ALPHA_LACK_OF_FIT
    text = (f"held-out RMS {d['rms_after']:.4f} mm against a floor of {floor.sigma_mm:.4f} mm ({floor.source}); "
            f"lack-of-fit p = {lof.p_value:.2g}")
    if above:
        lead = ""
        if leads:
            best = leads[0]
            conf = [c for c in confounded if best["name"] in c["terms"]]
            lead = (f"; {best['name']} would fit more of it (held-out {best['rms_mm']:.4f} mm) but was not added: "
                    f"{best['reason']}")
            if conf:
                lead += _separate(best["name"], conf[0])
        trend = (f"; {', '.join(d['trends'])}: a trend along the file's order was taken out, not as a cause (the "
                 "file has neither seq nor t_s)" if d.get("trends") else "")
        return False, (f"the final model does NOT explain the data: {text}; {d['unexplained']:.4f} mm unexplained"
                       + (f", strongest with: {where}" if where else "") + d.get("carried", "") + said + lead + trend)
    if d.get("rivals"):
        chosen, r = d["rivals"][0]
        return False, (f"not established: {text}, but a trend along the file's order ({r.name}, held-out "
                       f"{r.rms_mm:.4f} mm when {chosen} was added) fits the same residual about as well as {chosen}: "
                       "the file has neither seq nor t_s, so a drift during the measurements cannot be told from it; "
                       "add the measurement order or time and diagnose again")
    if d.get("trends"):
        return False, (f"not established: {text}, reached only with {', '.join(d['trends'])}: a trend along the "
                       "file's order, which is not known to be the order of measurement (the file has neither seq nor "
                       "t_s); add the measurement order or time and diagnose again")
    better = [r for r in leads if r["rms_mm"] < (1 - selection.MIN_GAIN["dictionary"]) * d["rms_after"]]
    if better:
        r = better[0]
        return False, (f"not established: {text}, but {r['name']} fits better (held-out {r['rms_mm']:.4f} mm) and "
                       f"was not added: {r['reason']}: the data carry something that looks like it"
                       + decides([r["name"]], confounded))
    if discovered:
        return False, (f"not established: {text}, reached only with terms found by searching {n_hyp} hypotheses "
                       f"({', '.join(discovered)})" + said + decides(discovered, confounded))
    out = f"the final model explains the data as far as the noise allows: {text}{said}"
    if floor.source == "stated" and lof.p_below < ALPHA_FLOOR_ABOVE:
        out += (f"; but the residual is {floor.sigma_mm / d['rms_after']:.1f}x below the stated floor "
                    f"(lower-tail p = {lof.p_below:.2g}): a floor that large hides any effect smaller than about "
                    f"{floor.sigma_mm:.4f} mm, so this says little; state the instrument's noise for a displacement")
    return True, out


def carried(terms, rms_before, rms_after, spread):
    """'; what lowers the held-out RMS, by how much, over the folds': the
    verdict says which terms carry the reduction and what kind they are."""
    if not terms:
        return "; no term of physical size was kept (the six springs are the final model)"
    named = [t["name"] for t in terms if t["source"] == "library"]
    found = [t["name"] for t in terms if t["source"] != "library"]
    beyond = [t["name"] for t in terms if t.get("beyond_typical")]
    kinds = "; ".join(([f"named: {', '.join(named)}"] if named else [])
                      + ([f"found in the dictionary, hypotheses to confirm: {', '.join(found)}"] if found else [])
                      + ([f"beyond the typical size on decisive evidence: {', '.join(beyond)}"] if beyond else []))
    size = "all of physical size" if not beyond else "physical in sign"
    out = (f"; the kept terms, {size} ({kinds}), lower the held-out RMS from {rms_before:.4f} to "
           f"{rms_after:.4f} mm ({100 * (1 - rms_after / rms_before):.0f} %")
    if spread is not None:
        out += (f"; {100 * spread['reduction_min']:.0f}-{100 * spread['reduction_max']:.0f} % over "
                f"{len(spread['seeds'])} fold assignments")
    return out + ")"


def _separate(name, pair):
    """'; it is confounded with B (correlation ...): ... plan-poses --separate A,B'."""
    other = next(t for t in pair["terms"] if t != name)
    return (f"; it is confounded with {other} (correlation of the estimates {pair['correlation']:+.2f}): the campaign "
            f"cannot separate them; the measurements that would are planned by robstiff plan-poses N --separate "
            f"{name},{other} --campaign DATA.csv")


def decides(names, confounded):
    """'; the measurement that would decide it' for the terms ``names``: the
    separating plan of the strongest confounded pair one of them is in, else
    a second campaign at other poses."""
    for pair in confounded:  # strongest first
        hit = [n for n in names if n in pair["terms"]]
        if hit:
            return _separate(hit[0], pair).replace("; it is", f"; {hit[0]} is", 1)
    return ("; what decides it: a second campaign at other poses (robstiff plan-poses N), diagnosed with the same "
            "noise, on which " + ("these hypotheses are" if len(names) > 1 else "this hypothesis is")
            + " tested again rather than chosen")


def too_few_poses(undecided, n_rows, n_poses):
    """'too few poses to decide: ...; what decides it.' for the candidates that
    would qualify but that the campaign's ``n_poses`` poses cannot test
    (candidate_evaluation: the pose-clustered test needs more poses than the
    model has parameters; selection.undecided)."""
    r = undecided[0]
    per_pose = max(1, round(n_rows / max(n_poses, 1)))
    more = max(r.poses_needed - n_poses, 1)
    return (f"too few poses to decide: {r.name} would lower the held-out RMS to {r.rms_mm:.4f} mm (nested F-test "
            f"p = {r.p_value:.2g}, rows taken as independent), but {n_poses} poses cannot test the "
            f"{r.poses_needed - 1} parameters of the model with it pose by pose (it needs at least {r.poses_needed}), "
            f"so no effect is named; what decides it: {more} or more further poses, e.g. robstiff plan-poses "
            f"{more * per_pose} (about {per_pose} loads per pose), added to this campaign and diagnosed again.")

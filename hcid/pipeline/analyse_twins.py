"""Phases 3 and 4 of ``hcid analyse`` (:mod:`hcid.pipeline.analyse`): every group's twins and
their calibration, and more FB twins wherever a run's p-value is not settled. Each phase makes
the twins of every forcing set of every group in one pool (:func:`hcid.pipeline.twins.calibrate_twin_sets`,
:func:`hcid.pipeline.twins.draw_fb_twin_sets`), so that the workers stay busy until its end."""

from __future__ import annotations

from collections.abc import Mapping

from hcid import methods
from hcid.config.fit import FEEDFORWARD_PARAMETERS
from hcid.pipeline.analyse_state import Found, Study
from hcid.pipeline.evidence import Evidence, group_name
from hcid.pipeline.line_statistics import LINE_STATISTICS
from hcid.pipeline.twins import (
    TwinSource,
    calibrate_twin_sets,
    draw_fb_twin_sets,
    forcing_sets,
    group_models,
    pool_twins,
    separates,
)

__all__ = ["make_twins", "more_fb_twins"]


def _twin_source(study: Study, found: Found, key, sets: list[list[int]], i: int, model: dict) -> TwinSource:
    """The twins of forcing set ``i`` (of a group's ``sets``): driven by its first run's record,
    the group's remnant; numbered from 1 only where the group has several sets."""
    record = study.records[sets[i][0]]
    number = i + 1 if len(sets) > 1 else 0
    config = study.plants.of_runs(study.groups[key])  # the group's plant
    return TwinSource(config, study.run_dir, key, record, model, found.remnants[key], study.kn_rate, number)


def _twin_sets(study: Study, found: Found, wanted: Mapping) -> dict:
    """Per group of ``wanted`` (group -> (kind, model, twins whose FB twin to share or None)): its
    twins of that kind for each of its forcing sets, pooled; every group's sets made in one pool."""
    requests, index = [], {}
    for key, (kind, model, fb_from) in wanted.items():
        runs_of_set = forcing_sets(study.groups[key], study.records, study.config)  # each set its own twins
        index[key] = (len(requests), runs_of_set, kind)
        for i in range(len(runs_of_set)):
            source = _twin_source(study, found, key, runs_of_set, i, model)
            requests.append((source, kind, fb_from.sets[i] if fb_from is not None else None))
    made = calibrate_twin_sets(requests, study.options.twins, study.execution) if requests else []
    return {
        key: pool_twins(kind, made[first : first + len(runs_of_set)], runs_of_set, study.config)
        for key, (first, runs_of_set, kind) in index.items()
    }


def make_twins(study: Study, found: Found) -> None:
    """Phase 3: per group, the twins and their calibration; which twins each method uses.

    The groups' models, and the study's strongest feedforward, come from the groups of each plant
    apart: a plant's groups are calibrated as a study of that plant alone would calibrate them."""
    strongest = {}
    for level, groups in study.plants.split(study.groups).items():
        models, remnants = group_models(study.plants.configs[level], groups, found.fitted)
        found.models.update(models)
        found.remnants.update(remnants)
        # The study's strongest feedforward (--ff-twin study and auto): the group with the largest
        # fitted Kpt ("would feedforward of the size seen in this study be found here?").
        strongest.update(dict.fromkeys(groups, max(groups, key=lambda k: models[k].values["Kpt"])))
    medians = {key: m.values for key, m in found.models.items()}
    ff_twin = study.options.ff_twin

    def study_model(key) -> dict:
        return {**medians[key], **{p: medians[strongest[key]][p] for p in FEEDFORWARD_PARAMETERS}}

    first = {key: "study" if ff_twin == "study" and key != strongest[key] else "own" for key in study.groups}
    earlier = _twin_sets(
        study,
        found,
        {key: (k, medians[key] if k == "own" else study_model(key), None) for key, k in first.items()},
    )
    # The study's FB twin is the own twins' (Kpt = 0: the same loop), shared, not made again.
    again = {
        key: ("study", study_model(key), earlier[key])
        for key in study.groups
        if ff_twin == "auto"
        and key != strongest[key]
        and not all(separates(c) for c in earlier[key].calibrations.values())
    }
    later = _twin_sets(study, found, again)
    for key in study.groups:
        for method_name in methods.METHODS:
            # The first twins where they separate; else the last made (study's, or the same).
            use = (
                earlier[key]
                if separates(earlier[key].calibrations[method_name])
                else later.get(key, earlier[key])
            )
            found.used[(key, method_name)] = use


def more_fb_twins(study: Study, found: Found, judge: Evidence, run_lines: dict) -> None:
    """Phase 4: more FB twins wherever a run's p-value is not settled (sequential, Besag and
    Clifford), in batches of ``twins``, up to ``max_fb_twins`` per forcing set; each round draws
    for every open forcing set of every group in one pool."""
    names, most, batch = tuple(methods.METHODS), study.options.most_fb_twins, study.options.twins
    judge.prefetch([(group_name(study.by, key), found.used[(key, m)]) for key in study.groups for m in names])
    open_sets = {}
    for key in study.groups:
        name, sets = group_name(study.by, key), found.used[(key, names[0])].runs
        found.deciding[key] = {m: judge.statistic(name, found.used[(key, m)], m) for m in names}
        for i, members in enumerate(sets):
            values = [
                ({m: judge.w_star(*found.paths[(s, m)][1:]) for m in names}, run_lines.get(s))
                for s in members
            ]
            source = _twin_source(study, found, key, sets, i, found.models[key].values)
            open_sets[(key, i)] = (name, {m: found.used[(key, m)].sets[i] for m in names}, values, source)
    waiting = list(open_sets)
    while waiting:
        requests = []
        for key, i in waiting:
            name, twin_of, values, source = open_sets[(key, i)]
            drawn = judge.drawn(name, i + 1, twin_of[names[0]])
            if drawn >= most:
                continue
            open_methods, lines_open = judge.unsettled(name, i + 1, twin_of, found.deciding[key], values)
            if open_methods or lines_open:
                requests.append(
                    ((key, i), (source, drawn + 1, min(batch, most - drawn), tuple(open_methods)))
                )
        waiting = [k for k, _ in requests]
        made = draw_fb_twin_sets([r for _, r in requests], study.execution) if requests else []
        for (key, i), draws in zip(waiting, made, strict=True):
            judge.add(open_sets[(key, i)][0], i + 1, draws)
        # The draws' line statistics, where one decides: every open set's in one pool.
        lines = [(key, i) for key, i in waiting if set(found.deciding[key].values()) & set(LINE_STATISTICS)]
        judge.prefetch_draws([(open_sets[(key, i)][0], i + 1) for key, i in lines])
    for (key, i), (name, twin_of, _, _) in open_sets.items():
        for m in names:
            if found.deciding[key][m] == "W*":
                n = judge.fb_thresholds(name, i + 1, twin_of[m], m).size
            else:
                n = judge.drawn(name, i + 1, twin_of[m])
            found.fb_drawn[(key, m)] = max(found.fb_drawn.get((key, m), 0), n)

"""Steps 3 and 4 of ``hcid analyse`` (:mod:`hcid.pipeline.analyse`): every group's twins and
their calibration, and more FB twins wherever a run's p-value is not settled. Each step makes
the twins of every forcing set of every group in one pool (:func:`hcid.pipeline.twins.calibrate_twin_sets`,
:func:`hcid.pipeline.twins.draw_fb_twin_sets`), so that the workers stay busy until its end."""

from __future__ import annotations

from collections.abc import Mapping

from hcid import methods
from hcid.config.fit_settings import FEEDFORWARD_PARAMETERS
from hcid.pipeline.analyse_state import Group, GroupTwins, RunPath, Study, Tested
from hcid.pipeline.evidence import Evidence, group_name
from hcid.pipeline.fit_hc import RunFits
from hcid.pipeline.line_statistics import LINE_STATISTICS
from hcid.pipeline.options import FfTwinChoice
from hcid.pipeline.twin_values import Remnant
from hcid.pipeline.twins import (
    FfTwin,
    TwinSets,
    TwinSource,
    calibrate_twin_sets,
    draw_fb_twin_sets,
    forcing_sets,
    group_models,
    pool_twins,
)
from hcid.selection.calibration import separates

__all__ = ["make_twins", "more_fb_twins"]


def _twin_source(
    study: Study, remnant: Remnant, key: Group, sets: list[list[int]], i: int, model: dict
) -> TwinSource:
    """The twins of forcing set ``i`` (of a group's ``sets``): driven by its first run's record,
    the group's remnant; numbered from 1 only where the group has several sets."""
    record = study.records[sets[i][0]]
    number = i + 1 if len(sets) > 1 else 0
    config = study.plants.of_runs(study.groups[key])  # the group's plant
    return TwinSource(config, study.run_dir, key, record, model, remnant, study.kn_rate, number)


def _twin_sets(study: Study, remnants: Mapping[Group, Remnant], wanted: Mapping) -> dict[Group, TwinSets]:
    """Per group of ``wanted`` (group -> (kind, model, twins whose FB twin to share or None)): its
    twins of that kind for each of its forcing sets, pooled; every group's sets made in one pool."""
    requests, index = [], {}
    for key, (kind, model, fb_from) in wanted.items():
        runs_of_set = forcing_sets(study.groups[key], study.records, study.config)  # each set its own twins
        index[key] = (len(requests), runs_of_set, kind)
        for i in range(len(runs_of_set)):
            source = _twin_source(study, remnants[key], key, runs_of_set, i, model)
            requests.append((source, kind, fb_from.sets[i] if fb_from is not None else None))
    made = calibrate_twin_sets(requests, study.options.twins, study.execution) if requests else []
    return {
        key: pool_twins(kind, made[first : first + len(runs_of_set)], runs_of_set, study.config)
        for key, (first, runs_of_set, kind) in index.items()
    }


def make_twins(study: Study, fitted: Mapping[int, RunFits]) -> dict[Group, GroupTwins]:
    """Step 3: per group, its model, the twins and their calibration; which twins each method uses.

    The groups' models, and the study's strongest feedforward, come from the groups of each plant
    apart: a plant's groups are calibrated as a study of that plant alone would calibrate them."""
    strongest, models, remnants = {}, {}, {}
    for level, groups in study.plants.split(study.groups).items():
        mine, remnant = group_models(study.plants.configs[level], groups, fitted)
        models.update(mine)
        remnants.update(remnant)
        # The study's strongest feedforward (--ff-twin study and auto): the group with the largest
        # fitted Kpt ("would feedforward of the size seen in this study be found here?").
        strongest.update(dict.fromkeys(groups, max(groups, key=lambda k: mine[k].values["Kpt"])))
    medians = {key: m.values for key, m in models.items()}
    ff_twin = study.options.ff_twin

    def study_model(key) -> dict:
        return {**medians[key], **{p: medians[strongest[key]][p] for p in FEEDFORWARD_PARAMETERS}}

    study_first = ff_twin == FfTwinChoice.STUDY
    first = {
        key: FfTwin.STUDY if study_first and key != strongest[key] else FfTwin.OWN for key in study.groups
    }
    earlier = _twin_sets(
        study,
        remnants,
        {key: (k, medians[key] if k is FfTwin.OWN else study_model(key), None) for key, k in first.items()},
    )
    # The study's FB twin is the own twins' (Kpt = 0: the same loop), shared, not made again.
    again = {
        key: (FfTwin.STUDY, study_model(key), earlier[key])
        for key in study.groups
        if ff_twin == FfTwinChoice.AUTO
        and key != strongest[key]
        and not all(separates(c) for c in earlier[key].calibrations.values())
    }
    later = _twin_sets(study, remnants, again)
    # Per method the first twins where they separate; else the last made (study's, or the same).
    return {
        key: GroupTwins(
            models[key],
            remnants[key],
            {
                m: earlier[key] if separates(earlier[key].calibrations[m]) else later.get(key, earlier[key])
                for m in methods.METHODS
            },
        )
        for key in study.groups
    }


def more_fb_twins(
    study: Study,
    twins: Mapping[Group, GroupTwins],
    paths: Mapping[tuple[int, str], RunPath],
    judge: Evidence,
    run_lines: dict,
) -> tuple[dict[Group, Tested], Evidence]:
    """Step 4: per group, the statistic that decides, and more FB twins wherever a run's p-value
    is not settled (sequential, Besag and Clifford), in batches of ``twins``, up to
    ``max_fb_twins`` per forcing set; each round draws for every open forcing set of every group
    in one pool. Returns each group's :class:`Tested` and ``judge`` with the calibration twins'
    line statistics and every round's draws (the evidence steps 5 and 6 read)."""
    names, most, batch = tuple(methods.METHODS), study.options.most_fb_twins, study.options.twins
    judge = judge.with_calibration_lines(
        [(group_name(study.by, key), twins[key].used[m]) for key in study.groups for m in names]
    )
    open_sets, deciding = {}, {}
    for key in study.groups:
        used = twins[key].used
        name, sets = group_name(study.by, key), used[names[0]].runs
        deciding[key] = {m: judge.statistic(name, used[m], m) for m in names}
        for i, members in enumerate(sets):
            values = [
                (
                    {m: judge.w_star(paths[(s, m)].path, paths[(s, m)].frontier.nb_ft) for m in names},
                    run_lines.get(s),
                )
                for s in members
            ]
            source = _twin_source(study, twins[key].remnant, key, sets, i, twins[key].model.values)
            open_sets[(key, i)] = (name, {m: used[m].sets[i] for m in names}, values, source)
    waiting = list(open_sets)
    while waiting:
        requests = []
        for key, i in waiting:
            name, twin_of, values, source = open_sets[(key, i)]
            drawn = judge.drawn(name, i + 1, twin_of[names[0]])
            if drawn >= most:
                continue
            open_methods, lines_open = judge.unsettled(name, i + 1, twin_of, deciding[key], values)
            if open_methods or lines_open:
                requests.append(
                    ((key, i), (source, drawn + 1, min(batch, most - drawn), tuple(open_methods)))
                )
        waiting = [k for k, _ in requests]
        made = draw_fb_twin_sets([r for _, r in requests], study.execution) if requests else []
        # The draws' line statistics where one decides: every open set's in one pool.
        judge = judge.with_draws(
            [
                (
                    open_sets[(key, i)][0],
                    i + 1,
                    draws,
                    bool(set(deciding[key].values()) & set(LINE_STATISTICS)),
                )
                for (key, i), draws in zip(waiting, made, strict=True)
            ]
        )
    fb_drawn: dict[Group, dict[str, int]] = {key: {} for key in study.groups}
    for (key, i), (name, twin_of, _, _) in open_sets.items():
        for m in names:
            if deciding[key][m] == "W*":
                n = judge.fb_thresholds(name, i + 1, twin_of[m], m).size
            else:
                n = judge.drawn(name, i + 1, twin_of[m])
            fb_drawn[key][m] = max(fb_drawn[key].get(m, 0), n)
    return {key: Tested(deciding[key], fb_drawn[key]) for key in study.groups}, judge

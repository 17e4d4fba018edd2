"""Design studies: many candidate trains, each analysed on its own, on a Dask cluster.

One module per job: :mod:`.spec` (the study file), :mod:`.candidates` (the design's
candidates as train files), :mod:`.analysis` (one candidate's analysis and figures of
merit), :mod:`.store` (one result file per candidate, gathered into one Dataset),
:mod:`.run` (the study on a cluster, or in this process).
"""

from .analysis import STATUSES as STATUSES, analyse_candidate as analyse_candidate
from .candidates import (
    Candidate as Candidate,
    candidate_train as candidate_train,
    candidates as candidates,
)
from .run import StudyResult as StudyResult, study as study
from .spec import StudySpec as StudySpec, load_study as load_study, loads_study as loads_study
from .store import load_study_results as load_study_results

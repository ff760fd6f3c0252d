"""The paper's studies as functions: parameter estimation, refrigerant-leak identification and
Sobol sensitivity, and local identifiability. Each returns its results (DataTrees, Datasets)
and, given a folder, writes them with their figures and tables; the ``pymc-vcc`` command runs
them.
"""

from pymc_vcc.studies.common import BUDGETS, Budget, StudySettings
from pymc_vcc.studies.estimate import EstimationResult, estimation_study
from pymc_vcc.studies.identify import IdentifyResult, identify_study
from pymc_vcc.studies.leak import LeakResult, leak_study
from pymc_vcc.studies.sobol import SobolResult, sobol_study
from pymc_vcc.studies.validation import ValidationResult, validation_study

__all__ = [
    "BUDGETS",
    "Budget",
    "EstimationResult",
    "IdentifyResult",
    "LeakResult",
    "SobolResult",
    "StudySettings",
    "ValidationResult",
    "estimation_study",
    "identify_study",
    "leak_study",
    "sobol_study",
    "validation_study",
]

import pytest

from eddiebot.vslam.errors import ParameterError
from eddiebot.vslam.parameters import RtabmapParameters, parameter_names


def test_defaults_match_rtabmap():
    p = RtabmapParameters()
    d = p.to_dict()
    assert d["Kp/DetectorStrategy"] == "8"
    assert d["Kp/MaxFeatures"] == "500"
    assert d["Vis/MaxFeatures"] == "1000"
    assert d["Vis/MinInliers"] == "20"
    assert d["Rtabmap/LoopThr"] == "0.11"
    assert d["Mem/STMSize"] == "10"
    assert d["RGBD/OptimizeMaxError"] == "3.0"
    assert d["Reg/Force3DoF"] == "false"
    assert d["RGBD/ProximityBySpace"] == "true"
    assert p.prediction_lc()[:3] == (0.1, 0.36, 0.30)
    assert len(parameter_names()) == len(d)


def test_round_trip_and_report_settings():
    p = RtabmapParameters.from_dict({
        "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "RGBD/AngularUpdate": "0.01",
        "RGBD/LinearUpdate": "0.01", "RGBD/ProximityBySpace": "false",
        "Mem/IncrementalMemory": "False",
    })
    assert p.reg_force_3dof and p.vis_min_inliers == 12
    assert not p.mem_incremental_memory
    assert RtabmapParameters.from_dict(p.to_dict()) == p


@pytest.mark.parametrize(
    "values",
    [{"Kp/NoSuchThing": "1"}, {"Vis/MinInliers": "abc"}, {"Kp/DetectorStrategy": "0"},
     {"Reg/Force3DoF": "maybe"}, {"Odom/Strategy": "5"}, {"Vis/MinInliers": "2.5"}],
)
def test_bad_parameters_raise(values):
    with pytest.raises(ParameterError):
        RtabmapParameters.from_dict(values)


def test_unknown_ignored_when_not_strict():
    p = RtabmapParameters.from_dict({"Optimizer/Strategy": "1", "Mem/STMSize": "30"}, strict=False)
    assert p.mem_stm_size == 30

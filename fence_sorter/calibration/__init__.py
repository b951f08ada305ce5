"""ROS-free calibration of the twin from measured bags (docs/guide/calibration.md).

``sensors`` emulates a real sorter's sensors on the twin's state, ``bag`` writes and reads the
measured topics, ``replay`` runs a recorded parcel on the twin, ``fit`` fits physics parameters
with confidence intervals and an identifiability verdict, ``validate`` predicts held-out
parcels, ``emulate`` makes bags with known truth and ``bench`` measures interval coverage.
"""

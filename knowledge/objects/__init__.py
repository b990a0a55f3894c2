"""Object recognition (book Sect. 7.3): SIFT features, a database of taught objects, and a
recogniser (ratio test, RANSAC homography) that finds them in camera images."""

from knowledge.objects.database import ObjectDatabase, ObjectEntry, TrainingView, class_name
from knowledge.objects.features import FeatureParams, Features, extract_features
from knowledge.objects.recognition import Detection, ObjectRecogniser, RecognitionParams

__all__ = [
    "Detection",
    "FeatureParams",
    "Features",
    "ObjectDatabase",
    "ObjectEntry",
    "ObjectRecogniser",
    "RecognitionParams",
    "TrainingView",
    "class_name",
    "extract_features",
]

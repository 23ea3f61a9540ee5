"""Your own two videos: frames, camera intrinsics, 2D keypoints and the time offset between the
drones, turned into a recording in the official layout that every other stage of the kit reads.

- :mod:`.frames`: a video file or a folder of images, decoded frame by frame (never all in memory).
- :mod:`.intrinsics`: ``K`` (and distortion) from OpenCV FileStorage, a small YAML/JSON of
  ``fx, fy, cx, cy``, or a default from the image size and a field of view; checked against the
  frames.
- :mod:`.keypoints`: a person's BODY_25 keypoints per frame from a file (the kit's pickle,
  OpenPose's JSON folder).
- :mod:`.offset`: the offset between the two videos from the cross-correlation of their
  keypoints' motion.
- :mod:`.assemble`: the two decoded videos, aligned by the offset, as a recording in the official
  layout (:mod:`airpose_lib.data.sequences.layout`).
- :mod:`.export`: a kit recording written as two videos and keypoint files (the known truth the
  video route is tested on).
"""

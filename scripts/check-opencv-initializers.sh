#!/usr/bin/env bash
# OpenCV's Mat::zeros, Mat::ones and Mat::eye build a matrix expression on an object that
# libopencv_core creates on first use, behind a guard the ThreadSanitizer build cannot see
# (the library is not instrumented). When two streaming threads make their first such call
# at once, the sanitizer reports a race on that object; CI failed on it once. The library
# and the plugin therefore construct with a fill value instead (cv::Mat1f(size, 0.f)).
# This check names any file under src/ or gst/ that calls one of the three; exit 1 if any.
# (cv::Matx's zeros and eye are plain inline code and are allowed.)
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root" || exit 1
hits=$(grep -rnE '\bMat([0-9][a-z]|_<[^>]*>)?::(zeros|ones|eye)\(' src gst)
if [ -n "$hits" ]; then
  echo "Construct with a fill value instead of Mat::zeros/ones/eye (see this script's comment):"
  echo "$hits"
  exit 1
fi
echo "no Mat::zeros, Mat::ones or Mat::eye in src/ and gst/"

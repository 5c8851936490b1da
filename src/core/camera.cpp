// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag/camera.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <tuple>

#include <opencv2/calib3d.hpp>

#include "calibration_file.hpp"

namespace lftag {
namespace {

// A number for a message, whatever the C locale says about decimal points.
std::string show(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 6);
  return std::string(buf, r.ptr);
}

// Closes the file it holds when it goes out of scope.
struct FileDescriptor {
  explicit FileDescriptor(int f) : fd(f) {}
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  ~FileDescriptor() {
    if (fd >= 0) ::close(fd);
  }
  const int fd;
};

}  // namespace

Camera Camera::default_for(int width, int height) {
  Camera cam = pinhole(width, width, (width - 1) / 2.0, (height - 1) / 2.0, width, height);
  cam.calibrated = false;
  return cam;
}

Camera Camera::pinhole(double fx, double fy, double cx, double cy, int width, int height) {
  Camera cam;
  cam.fx = fx, cam.fy = fy, cam.cx = cx, cam.cy = cy;
  cam.width = width, cam.height = height;
  cam.calibrated = true;
  return cam;
}

bool operator==(const Camera& a, const Camera& b) {
  return std::tie(a.fx, a.fy, a.cx, a.cy, a.width, a.height, a.distortion, a.calibrated) ==
         std::tie(b.fx, b.fy, b.cx, b.cy, b.width, b.height, b.distortion, b.calibrated);
}

std::optional<Camera> PinholeSettings::camera_for(int width, int height) const {
  if (!fx) return std::nullopt;
  Camera camera = Camera::pinhole(*fx, fy.value_or(*fx), cx.value_or((width - 1) / 2.0),
                                  cy.value_or((height - 1) / 2.0), width, height);
  camera.distortion = distortion;
  return camera;
}

bool operator==(const PinholeSettings& a, const PinholeSettings& b) {
  return std::tie(a.fx, a.fy, a.cx, a.cy, a.distortion) == std::tie(b.fx, b.fy, b.cx, b.cy, b.distortion);
}

Camera Camera::load(const std::string& path) {
  const std::string name = "calibration file '" + path + "'";
  // Refused before anything is opened: opening a FIFO waits for a writer (forever, for
  // one that has none), and opening a device can act on it.
  if (const std::string problem = detail::not_a_regular_file(path); !problem.empty())
    throw std::runtime_error(name + " cannot be opened: it " + problem +
                             (detail::names_a_kind(problem) ? ", expected a regular file" : ""));
  // Should the path have become a FIFO since, O_NONBLOCK keeps the open from waiting, and
  // fstat tells what was opened.
  const FileDescriptor file{::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_NOCTTY | O_CLOEXEC)};
  const int fd = file.fd;
  if (fd < 0) throw std::runtime_error(name + " cannot be opened: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode))
    throw std::runtime_error(name + " cannot be opened: it is not a regular file");
  // One byte more than the limit tells a file that is too big (or endless) from one that fits.
  std::string text(detail::kMaxCalibrationBytes + 1, '\0');
  std::size_t size = 0;
  while (size < text.size()) {
    const ssize_t n = ::read(fd, text.data() + size, text.size() - size);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw std::runtime_error(name + " cannot be read: " + std::strerror(errno));
    if (n == 0) break;
    size += std::size_t(n);
  }
  text.resize(size);
  if (text.size() > detail::kMaxCalibrationBytes)
    throw std::runtime_error(name + " is larger than the " + std::to_string(detail::kMaxCalibrationBytes) +
                             " bytes (1 MiB) a calibration file may have");
  try {
    return detail::read_calibration(text);
  } catch (const std::exception& e) {
    throw std::runtime_error(name + ": " + e.what());
  }
}

Camera Camera::parse(const std::string& text, const std::string& source) {
  try {
    return detail::read_calibration(text);
  } catch (const std::exception& e) {
    throw std::runtime_error(source + ": " + e.what());
  }
}

void Camera::save(const std::string& path) const {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw std::runtime_error("cannot write calibration file '" + path + "'");
  if (width > 0) fs << "image_width" << width;
  if (height > 0) fs << "image_height" << height;
  fs << "camera_matrix" << cv::Mat(matrix());
  fs << "distortion_coefficients" << (distortion.empty() ? cv::Mat(1, 5, CV_64F, cv::Scalar(0)) : distortion_mat());
}

Camera Camera::for_frame(int frame_width, int frame_height) const {
  if (width <= 0 || height <= 0 || (width == frame_width && height == frame_height)) {
    Camera c = *this;
    c.width = frame_width, c.height = frame_height;
    return c;
  }
  const double sx = double(frame_width) / width, sy = double(frame_height) / height;
  if (std::abs(sx - sy) > 0.01 * std::max(sx, sy))
    throw std::invalid_argument("the calibration is for " + std::to_string(width) + "x" + std::to_string(height) +
                                " frames and cannot be scaled to " + std::to_string(frame_width) + "x" +
                                std::to_string(frame_height));
  Camera c = *this;
  // Scale about pixel edges: a pixel centre x maps to (x + 0.5) * s - 0.5.
  c.fx *= sx, c.fy *= sy;
  c.cx = (cx + 0.5) * sx - 0.5, c.cy = (cy + 0.5) * sy - 0.5;
  c.width = frame_width, c.height = frame_height;
  return c;
}

bool Camera::has_distortion() const {
  for (double d : distortion)
    if (d != 0.0) return true;
  return false;
}

cv::Matx33d Camera::matrix() const { return {fx, 0, cx, 0, fy, cy, 0, 0, 1}; }

cv::Mat Camera::distortion_mat() const {
  if (!has_distortion()) return {};
  cv::Mat d(1, int(distortion.size()), CV_64F);
  for (std::size_t i = 0; i < distortion.size(); ++i) d.at<double>(0, int(i)) = distortion[i];
  return d;
}

std::vector<cv::Point2d> Camera::undistort(const std::vector<cv::Point2d>& pixels) const {
  if (!has_distortion() || pixels.empty()) return pixels;
  std::vector<cv::Point2d> out;
  const cv::Matx33d k = matrix();
  cv::undistortPoints(pixels, out, k, distortion_mat(), cv::noArray(), k,
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 1e-10));
  return out;
}

std::vector<cv::Point2d> Camera::project(const std::vector<cv::Point3d>& points, const cv::Vec3d& rvec,
                                         const cv::Vec3d& tvec) const {
  std::vector<cv::Point2d> out;
  if (points.empty()) return out;
  cv::projectPoints(points, rvec, tvec, matrix(), distortion_mat(), out);
  return out;
}

void Camera::validate() const {
  auto in = [](double v, double lo, double hi) { return v >= lo && v <= hi; };  // false for NaN
  if (!in(fx, kMinFocal, kMaxFocal) || !in(fy, kMinFocal, kMaxFocal))
    throw std::invalid_argument("the focal lengths (fx = " + show(fx) + ", fy = " + show(fy) +
                                ") are out of range, expected " + show(kMinFocal) + " to " + show(kMaxFocal) +
                                " pixels");
  if (!in(cx, -kMaxPrincipal, kMaxPrincipal) || !in(cy, -kMaxPrincipal, kMaxPrincipal))
    throw std::invalid_argument("the principal point (cx = " + show(cx) + ", cy = " + show(cy) +
                                ") is out of range, expected finite numbers from " + show(-kMaxPrincipal) + " to " +
                                show(kMaxPrincipal) + " pixels");
  if (width < 0 || height < 0 || width > kMaxImageSide || height > kMaxImageSide)
    throw std::invalid_argument("the image size " + std::to_string(width) + "x" + std::to_string(height) +
                                " is out of range, expected 0 (unknown) to " + std::to_string(kMaxImageSide) +
                                " pixels a side");
  const std::size_t n = distortion.size();
  if (n != 0 && n != 4 && n != 5 && n != 8)
    throw std::invalid_argument("there are " + std::to_string(n) +
                                " distortion coefficients, expected none, 4, 5 or 8 (k1 k2 p1 p2 [k3 [k4 k5 k6]])");
  for (std::size_t i = 0; i < n; ++i)
    if (!in(distortion[i], -kMaxDistortion, kMaxDistortion))
      throw std::invalid_argument("distortion coefficient " + std::to_string(i + 1) + " (" + show(distortion[i]) +
                                  ") is out of range, expected finite numbers from " + show(-kMaxDistortion) + " to " +
                                  show(kMaxDistortion));
}

}  // namespace lftag

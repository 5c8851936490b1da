// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag/camera.hpp"

#include <cmath>
#include <fstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

namespace lftag {
namespace {

// Reads the first present key of `names` as a matrix; empty if none is present.
cv::Mat read_matrix(const cv::FileStorage& fs, std::initializer_list<const char*> names) {
  for (const char* name : names) {
    cv::FileNode node = fs[name];
    if (node.empty()) continue;
    cv::Mat m;
    node >> m;
    if (m.empty()) throw std::runtime_error(std::string("'") + name + "' is not a matrix");
    m.convertTo(m, CV_64F);
    return m;
  }
  return {};
}

int read_int(const cv::FileStorage& fs, const char* name) {
  cv::FileNode node = fs[name];
  if (node.empty()) return 0;
  if (!node.isInt() && !node.isReal()) throw std::runtime_error(std::string("'") + name + "' is not a number");
  return int(node.real());
}

Camera from_storage(const cv::FileStorage& fs) {
  const cv::Mat k = read_matrix(fs, {"camera_matrix", "cameraMatrix"});
  if (k.empty())
    throw std::runtime_error("no 'camera_matrix' (or 'cameraMatrix') entry");
  if (k.rows != 3 || k.cols != 3)
    throw std::runtime_error("the camera matrix is " + std::to_string(k.rows) + "x" +
                             std::to_string(k.cols) + ", expected 3x3");
  Camera cam;
  cam.fx = k.at<double>(0, 0);
  cam.fy = k.at<double>(1, 1);
  cam.cx = k.at<double>(0, 2);
  cam.cy = k.at<double>(1, 2);
  const cv::Mat d = read_matrix(fs, {"distortion_coefficients", "distCoeffs"});
  if (!d.empty()) {
    if (d.total() != 4 && d.total() != 5 && d.total() != 8)
      throw std::runtime_error("the distortion has " + std::to_string(d.total()) +
                               " coefficients, expected 4, 5 or 8 (k1 k2 p1 p2 [k3 [k4 k5 k6]])");
    cam.distortion.assign(d.ptr<double>(), d.ptr<double>() + d.total());
  }
  cam.width = read_int(fs, "image_width");
  cam.height = read_int(fs, "image_height");
  cam.calibrated = true;
  cam.validate();
  return cam;
}

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

Camera Camera::load(const std::string& path) {
  std::ifstream probe(path);
  if (!probe) throw std::runtime_error("calibration file '" + path + "' cannot be opened");
  try {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    if (!fs.isOpened()) throw std::runtime_error("it is not an OpenCV YAML, XML or JSON file");
    return from_storage(fs);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("calibration file '" + path + "' cannot be parsed: " + e.err);
  } catch (const std::exception& e) {
    throw std::runtime_error("calibration file '" + path + "': " + e.what());
  }
}

Camera Camera::parse(const std::string& text, const std::string& source) {
  try {
    cv::FileStorage fs(text, cv::FileStorage::READ | cv::FileStorage::MEMORY);
    if (!fs.isOpened()) throw std::runtime_error("it is not OpenCV YAML, XML or JSON");
    return from_storage(fs);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(source + " cannot be parsed: " + e.err);
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
  fs << "distortion_coefficients" << (distortion.empty() ? cv::Mat::zeros(1, 5, CV_64F) : distortion_mat());
}

Camera Camera::for_frame(int frame_width, int frame_height) const {
  if (width <= 0 || height <= 0 || (width == frame_width && height == frame_height)) {
    Camera c = *this;
    c.width = frame_width, c.height = frame_height;
    return c;
  }
  const double sx = double(frame_width) / width, sy = double(frame_height) / height;
  if (std::abs(sx - sy) > 0.01 * std::max(sx, sy))
    throw std::invalid_argument("the calibration is for " + std::to_string(width) + "x" +
                                std::to_string(height) + " frames and cannot be scaled to " +
                                std::to_string(frame_width) + "x" + std::to_string(frame_height));
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
  auto finite = [](double v) { return std::isfinite(v); };
  if (!(finite(fx) && finite(fy) && fx > 0 && fy > 0))
    throw std::invalid_argument("focal lengths must be positive (fx = " + std::to_string(fx) +
                                ", fy = " + std::to_string(fy) + ")");
  if (!finite(cx) || !finite(cy)) throw std::invalid_argument("principal point is not finite");
  if (width < 0 || height < 0) throw std::invalid_argument("image size must not be negative");
  for (double d : distortion)
    if (!finite(d)) throw std::invalid_argument("distortion coefficients must be finite");
}

}  // namespace lftag

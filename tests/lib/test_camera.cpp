// SPDX-License-Identifier: LGPL-2.1-or-later
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "lftag/camera.hpp"

#include "errors.hpp"

using lftag::Camera;

namespace {
const std::string kData = LFTAG_TEST_DATA;

// The error Camera::load gives `path` ("" if it loads).
std::string load_error(const std::string& path) {
  return error_of([&] { Camera::load(path); });
}

// The error Camera::parse gives `text` ("" if it loads).
std::string parse_error(const std::string& text) {
  return error_of([&] { Camera::parse(text, "inline"); });
}

std::string write_temp(const std::string& name, const std::string& bytes) {
  const std::string path = testing::TempDir() + "/" + name;
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

// A valid OpenCV YAML calibration with `entries` appended.
std::string yaml_with(const std::string& matrix_data, const std::string& entries = "") {
  return "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ " + matrix_data +
         " ]\n" + entries;
}
const std::string kGoodK = "600., 0., 319.5, 0., 600., 239.5, 0., 0., 1.";
// The same in XML and JSON, with `entries` after it.
std::string xml_with(const std::string& entries) {
  return "<?xml version=\"1.0\"?>\n<opencv_storage>\n<camera_matrix type_id=\"opencv-matrix\"><rows>3</rows>"
         "<cols>3</cols><dt>d</dt><data>600. 0. 319.5 0. 600. 239.5 0. 0. 1.</data></camera_matrix>\n" +
         entries + "</opencv_storage>\n";
}
std::string json_with(const std::string& entries) {
  return "{\"camera_matrix\": {\"type_id\": \"opencv-matrix\", \"rows\": 3, \"cols\": 3, \"dt\": \"d\", "
         "\"data\": [600.0, 0.0, 319.5, 0.0, 600.0, 239.5, 0.0, 0.0, 1.0]}" +
         entries + "}";
}

}  // namespace

// The hand-set camera: fy defaults to fx, the principal point to the frame's centre, a
// principal point of 0 is 0, and without fx there is none.
TEST(Camera, PinholeSettingsFillWhatIsNotSet) {
  lftag::PinholeSettings pin;
  EXPECT_FALSE(pin.camera_for(640, 480));
  pin.fy = 500;
  pin.cx = 10;
  EXPECT_FALSE(pin.camera_for(640, 480)) << "fy and cx without fx";
  pin = {};
  pin.fx = 600;
  auto camera = pin.camera_for(640, 480);
  ASSERT_TRUE(camera);
  EXPECT_EQ(camera->fx, 600);
  EXPECT_EQ(camera->fy, 600);
  EXPECT_EQ(camera->cx, 319.5);
  EXPECT_EQ(camera->cy, 239.5);
  EXPECT_EQ(camera->width, 640);
  EXPECT_TRUE(camera->calibrated);
  EXPECT_FALSE(camera->has_distortion());
  pin.fy = 610;
  pin.cy = 0;
  pin.distortion = {-0.1, 0.01, 0, 0};
  camera = pin.camera_for(640, 480);
  ASSERT_TRUE(camera);
  EXPECT_EQ(camera->fy, 610);
  EXPECT_EQ(camera->cx, 319.5);
  EXPECT_EQ(camera->cy, 0);
  EXPECT_EQ(camera->distortion, pin.distortion);
  EXPECT_NO_THROW(camera->validate());
  lftag::PinholeSettings other = pin;
  EXPECT_EQ(other, pin);
  other.cy.reset();
  EXPECT_NE(other, pin);
  EXPECT_NE(*other.camera_for(640, 480), *camera);
  EXPECT_EQ(*pin.camera_for(640, 480), *camera);
}

TEST(Camera, LoadsOpenCvSampleCalibration) {
  const Camera c = Camera::load(kData + "/opencv_sample.yml");
  EXPECT_TRUE(c.calibrated);
  EXPECT_DOUBLE_EQ(c.fx, 628.158);
  EXPECT_DOUBLE_EQ(c.cy, 260.908);
  EXPECT_EQ(c.width, 640);
  ASSERT_EQ(c.distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(c.distortion[1], -0.206384);
}

TEST(Camera, LoadsGStreamerCameraCalibrateKeys) {
  const Camera c = Camera::load(kData + "/gst_cameracalibrate.xml");
  EXPECT_DOUBLE_EQ(c.fx, 800);
  EXPECT_DOUBLE_EQ(c.cx, 319.5);
  EXPECT_DOUBLE_EQ(c.distortion[0], -0.1);
  EXPECT_EQ(c.width, 0);  // unknown
}

TEST(Camera, ErrorsNameTheFileAndTheProblem) {
  const std::string missing = load_error(kData + "/does-not-exist.yml");
  EXPECT_NE(missing.find("does-not-exist.yml"), std::string::npos);
  EXPECT_NE(missing.find("cannot be opened"), std::string::npos);
  const std::string malformed = load_error(kData + "/malformed.yml");
  EXPECT_NE(malformed.find("malformed.yml"), std::string::npos);
  const std::string shape = load_error(kData + "/wrong_shape.yml");
  EXPECT_NE(shape.find("expected 3x3"), std::string::npos) << shape;
  const std::string none = load_error(kData + "/no_matrix.yml");
  EXPECT_NE(none.find("camera_matrix"), std::string::npos) << none;
}

TEST(Camera, ParsesAndSavesRoundTrip) {
  Camera c = Camera::pinhole(500, 510, 320, 240, 640, 480);
  c.distortion = {0.1, -0.05, 0.001, 0.002, 0.01};
  const std::string path = testing::TempDir() + "/cam.yml";
  c.save(path);
  const Camera d = Camera::load(path);
  EXPECT_DOUBLE_EQ(d.fy, 510);
  EXPECT_EQ(d.height, 480);
  EXPECT_EQ(d.distortion, c.distortion);
  EXPECT_THROW(Camera::parse("camera_matrix: 5", "inline"), std::runtime_error);
}

TEST(Camera, UndistortInvertsProjection) {
  Camera c = Camera::load(kData + "/opencv_sample.yml");
  std::vector<cv::Point3d> pts;
  for (double x = -0.4; x <= 0.4; x += 0.1)
    for (double y = -0.3; y <= 0.3; y += 0.1) pts.emplace_back(x, y, 1.0);
  const auto distorted = c.project(pts);
  const auto ideal = c.undistort(distorted);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    EXPECT_NEAR(ideal[i].x, c.fx * pts[i].x + c.cx, 1e-6);
    EXPECT_NEAR(ideal[i].y, c.fy * pts[i].y + c.cy, 1e-6);
  }
}

TEST(Camera, DefaultAndScaledCameras) {
  const Camera d = Camera::default_for(1280, 720);
  EXPECT_FALSE(d.calibrated);
  EXPECT_DOUBLE_EQ(d.fx, 1280);
  EXPECT_DOUBLE_EQ(d.cx, 639.5);
  EXPECT_DOUBLE_EQ(d.cy, 359.5);
  const Camera c = Camera::pinhole(600, 600, 319.5, 239.5, 640, 480).for_frame(1280, 960);
  EXPECT_DOUBLE_EQ(c.fx, 1200);
  EXPECT_DOUBLE_EQ(c.cx, 639.5);
  EXPECT_THROW(Camera::pinhole(600, 600, 319.5, 239.5, 640, 480).for_frame(1280, 720), std::invalid_argument);
  EXPECT_THROW(Camera::pinhole(0, 600, 1, 1).validate(), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// Hostile and broken calibration files: each is a std::runtime_error naming the file
// (or the source) and the problem; none reaches cv::FileStorage.

TEST(CameraFile, ReproducersOfOpenCvParserFailures) {
  // A NUL byte in an XML attribute crashed OpenCV's parser.
  std::string e = load_error(kData + "/nul_byte.xml");
  EXPECT_MENTIONS(e, "nul_byte.xml");
  EXPECT_MENTIONS(e, "NUL byte");
  // OpenCV's YAML parser never returned on this.
  e = error_within([] { Camera::load(kData + "/hangs_opencv.yml"); });
  EXPECT_MENTIONS(e, "hangs_opencv.yml");
  EXPECT_MENTIONS(e, "not valid YAML: line 4");
  e = error_within([] { Camera::parse("%YAML:1.0\na: 1\n...-. ]", "inline"); });
  EXPECT_MENTIONS(e, "inline: it is not valid YAML");
  // 10^16 elements: refused by their count before anything is allocated.
  e = load_error(kData + "/huge_matrix.yml");
  EXPECT_MENTIONS(e, "huge_matrix.yml");
  EXPECT_MENTIONS(e, "is 100000000x100000000, expected 3x3");
  e = parse_error(yaml_with(kGoodK,
                            "distortion_coefficients: !!opencv-matrix\n   rows: 100000000\n   cols: "
                            "100000000\n   dt: d\n   data: [ 0. ]\n"));
  EXPECT_MENTIONS(e, "expected 4, 5 or 8");
  // Declared small, but with many values: the reading stops at 256.
  std::string many;
  for (int i = 0; i < 100000; ++i) many += "1., ";
  e = parse_error(yaml_with(many + "1."));
  EXPECT_MENTIONS(e, "more than 256 values");
  std::string many_json;
  for (int i = 0; i < 100000; ++i) many_json += "1, ";
  e = parse_error(
      "{\"camera_matrix\": {\"type_id\": \"opencv-matrix\", \"rows\": 3, \"cols\": 3, \"dt\": \"d\", "
      "\"data\": [" +
      many_json + "1]}}");
  EXPECT_MENTIONS(e, "more than 256 values");
}

TEST(CameraFile, ImageSizeMustBeAWholeNumberInRange) {
  for (const char* bad : {".nan", ".NaN", "1e300", "-1", "640.5", "65537", "abc", "\"640\"", "[640]", "1e999"}) {
    const std::string e = parse_error(yaml_with(kGoodK, std::string("image_width: ") + bad + "\n"));
    EXPECT_MENTIONS(e, "inline: 'image_width'");
    EXPECT_MENTIONS(e, "expected");
  }
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, "image_height: -480\n")),
                  "'image_height' is '-480', expected a whole number of pixels from 0 to 65536");
  // The limits themselves load; 0 is "unknown".
  EXPECT_EQ(Camera::parse(yaml_with(kGoodK, "image_width: 65536\nimage_height: 0\n")).width, 65536);
  // XML and JSON go through the same checks.
  EXPECT_MENTIONS(parse_error(xml_with("<image_width>1e300</image_width>")), "'image_width' is '1e300'");
  EXPECT_MENTIONS(parse_error(xml_with("<image_width>640.5</image_width>")), "'image_width' is '640.5'");
  EXPECT_MENTIONS(parse_error(json_with(", \"image_width\": 1e300")), "'image_width' is '1e+300'");
  EXPECT_MENTIONS(parse_error(json_with(", \"image_width\": -640")), "'image_width' is '-640'");
}

TEST(CameraFile, IntrinsicsMustBeFiniteAndInRange) {
  EXPECT_MENTIONS(parse_error(yaml_with("1e-300, 0., 319.5, 0., 600., 239.5, 0., 0., 1.")),
                  "the focal lengths (fx = 1e-300, fy = 600) are out of range, expected 0.001 to 1e+07 pixels");
  EXPECT_MENTIONS(parse_error(yaml_with("-600, 0., 319.5, 0., 600., 239.5, 0., 0., 1.")), "focal lengths");
  EXPECT_MENTIONS(parse_error(yaml_with("600., 0., 1e300, 0., 600., 239.5, 0., 0., 1.")), "principal point");
  for (const char* bad : {".nan", ".inf", "-.Inf", "nan", "inf", "1e999", "0x10", "1;5", "'600'", "six", "[1]"}) {
    const std::string e = parse_error(yaml_with(std::string(bad) + ", 0., 319.5, 0., 600., 239.5, 0., 0., 1."));
    EXPECT_MENTIONS(e, "'camera_matrix' data item 1");
  }
  EXPECT_MENTIONS(parse_error(yaml_with("600., 0., 319.5, 0., 600., .nan, 0., 0., 1.")),
                  "'camera_matrix' data item 6 is '.nan', expected a finite number");
  // No skew, and a last row of 0 0 1.
  EXPECT_MENTIONS(parse_error(yaml_with("600., 3., 319.5, 0., 600., 239.5, 0., 0., 1.")), "skew is not supported");
  EXPECT_MENTIONS(parse_error(yaml_with("600., 0., 319.5, 0., 600., 239.5, 0., 0., 2.")), "[fx 0 cx; 0 fy cy; 0 0 1]");
  // Distortion: finite, bounded, 4, 5 or 8 coefficients in one row or column.
  const std::string d = "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: ";
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, d + "4\n   dt: d\n   data: [ 0.1, .nan, 0, 0 ]\n")),
                  "'distortion_coefficients' data item 2 is '.nan', expected a finite number");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, d + "4\n   dt: d\n   data: [ 0.1, 1e5, 0, 0 ]\n")),
                  "distortion coefficient 2 (100000) is out of range");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, d + "6\n   dt: d\n   data: [ 0, 0, 0, 0, 0, 0 ]\n")),
                  "has 6 coefficients, expected 4, 5 or 8");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, d + "12\n   dt: d\n   data: [ 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0 ]\n")),
                  "thin-prism (12) and tilted-sensor (14) models are not supported");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK,
                                        "distortion_coefficients: !!opencv-matrix\n   rows: 2\n   cols: 2\n"
                                        "   dt: d\n   data: [ 0, 0, 0, 0 ]\n")),
                  "is 2x2, expected 4, 5 or 8 coefficients in one row or column");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, d + "4\n   dt: d\n   data: [ 0, 0, 0 ]\n")),
                  "'distortion_coefficients' data is a list of 3 values, expected 4 numbers (1x4)");
  // dt f values beyond a float.
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, d + "4\n   dt: f\n   data: [ 0, 0, 0, 1e39 ]\n")), "dt f");
}

TEST(CameraFile, NestingAliasesAndEntitiesAreRefused) {
  // Deep nesting, in a key that is read and in one that is skipped.
  const std::string deep = std::string(100, '[') + std::string(100, ']');
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, "other: " + deep + "\n")), "nests deeper than 32 levels");
  EXPECT_MENTIONS(parse_error("%YAML:1.0\ncamera_matrix: " + deep + "\n"), "nests deeper than 32 levels");
  EXPECT_MENTIONS(parse_error("{\"other\": " + deep + "}"), "nests deeper than 32 levels");
  std::string xml = "<?xml version=\"1.0\"?><opencv_storage>";
  for (int i = 0; i < 100; ++i) xml += "<a>";
  for (int i = 0; i < 100; ++i) xml += "</a>";
  EXPECT_MENTIONS(parse_error(xml + "</opencv_storage>"), "nests deeper than 32 levels");
  // Very deep nesting is a clean error too (no recursion in any of the parsers' paths).
  const std::string very_deep = std::string(200000, '[') + std::string(200000, ']');
  EXPECT_MENTIONS(parse_error("%YAML:1.0\nother: " + very_deep + "\n"), "nests deeper");
  EXPECT_MENTIONS(parse_error("{\"other\": " + very_deep + "}"), "nests deeper");

  // A YAML "billion laughs": anchors and aliases are refused, not expanded.
  std::string bomb = "%YAML:1.0\na0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n";
  for (int i = 1; i < 10; ++i)
    bomb += "a" + std::to_string(i) + ": &a" + std::to_string(i) + " [*a" + std::to_string(i - 1) + ", *a" +
            std::to_string(i - 1) + ", *a" + std::to_string(i - 1) + ", *a" + std::to_string(i - 1) + "]\n";
  bomb += "camera_matrix: *a9\n";
  std::string e = error_within([&] { Camera::parse(bomb, "bomb.yml"); });
  EXPECT_MENTIONS(e, "bomb.yml: it uses a YAML anchor (&a0)");
  e = parse_error(yaml_with(kGoodK, "distortion_coefficients: *k\n"));
  EXPECT_MENTIONS(e, "YAML alias (*k)");

  // An XML "billion laughs" and an external entity: no document type at all.
  std::string laughs = "<?xml version=\"1.0\"?>\n<!DOCTYPE lolz [\n<!ENTITY lol \"lol\">\n";
  for (int i = 1; i < 10; ++i) {
    laughs += "<!ENTITY lol" + std::to_string(i) + " \"";
    for (int j = 0; j < 10; ++j) laughs += "&lol" + (i > 1 ? std::to_string(i - 1) : std::string()) + ";";
    laughs += "\">\n";
  }
  laughs += "]>\n<opencv_storage><image_width>&lol9;</image_width></opencv_storage>\n";
  e = error_within([&] { Camera::parse(laughs, "lolz.xml"); });
  EXPECT_MENTIONS(e, "lolz.xml: it has an XML document type or entity declaration");
  e = parse_error(
      "<?xml version=\"1.0\"?><!DOCTYPE x SYSTEM \"file:///etc/passwd\"><opencv_storage>"
      "</opencv_storage>");
  EXPECT_MENTIONS(e, "document type");
  // Entities that are not declared are XML errors.
  e = parse_error("<?xml version=\"1.0\"?><opencv_storage><image_width>&x;</image_width></opencv_storage>");
  EXPECT_MENTIONS(e, "not valid XML");
}

// `text`, then what `item(0)`, `item(1)`... make, as many as fit under 1 MiB with `tail`.
std::string fill_to_limit(std::string text, const std::function<std::string(int)>& item, const std::string& tail) {
  for (int i = 0;; ++i) {
    const std::string next = item(i);
    if (text.size() + next.size() + tail.size() > (1u << 20)) break;
    text += next;
  }
  return text + tail;
}

// Distinct short names: a, b, ..., Z, ba, bb, ...
std::string name_of(int i) {
  const char* letters = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ";
  std::string name;
  do name += letters[i % 52], i /= 52;
  while (i > 0);
  return name;
}

TEST(CameraFile, XmlAttributesAndNestingAreBoundedBeforeLibxml2) {
  // libxml2 compares each attribute of an element with all those before it: 150,000 on one
  // element (1 MiB) did not finish in a minute, 75,000 namespace declarations took 1.2 s.
  // A linear pass before libxml2 refuses more than 8 on one element.
  const std::string head = "<?xml version=\"1.0\"?>\n<opencv_storage>\n<other";
  const std::string tail = "/>\n</opencv_storage>\n";
  const std::string attributes = fill_to_limit(
      head, [](int i) { return " " + name_of(i) + "=\"\""; }, tail);
  std::string e = error_within([&] { Camera::parse(attributes, "attributes.xml"); });
  EXPECT_MENTIONS(e, "attributes.xml: the XML element '<other>' has more than 8 attributes");
  const std::string namespaces = fill_to_limit(
      head, [](int i) { return " xmlns:" + name_of(i) + "=\"u\""; }, tail);
  EXPECT_MENTIONS(error_within([&] { Camera::parse(namespaces, "ns.xml"); }), "has more than 8 attributes");
  // The attributes OpenCV writes are read.
  EXPECT_EQ(parse_error(xml_with("<other a=\"1\" b='2' c=\"x=y\"/>\n")), "");
  // Deep nesting is refused by the same pass (libxml2 stops at 256 levels, after them).
  std::string deep = "<?xml version=\"1.0\"?><opencv_storage>";
  for (int i = 0; i < 100000; ++i) deep += "<a>";
  EXPECT_MENTIONS(parse_error(deep), "nests deeper than 32 levels");
}

TEST(CameraFile, EveryFormatHasAtMost20000Nodes) {
  // Every node costs each parser an allocation or two: at most 20,000 in a file.
  const std::string elements = fill_to_limit(
      xml_with("").substr(0, xml_with("").size() - 18), [](int) { return "<a/>"; }, "</opencv_storage>\n");
  EXPECT_MENTIONS(parse_error(elements), "more than 20000 XML elements, attributes, comments and references");
  const std::string comments = fill_to_limit(
      xml_with("").substr(0, xml_with("").size() - 18), [](int) { return "<!---->"; }, "</opencv_storage>\n");
  EXPECT_MENTIONS(parse_error(comments), "more than 20000 XML elements");
  const std::string keys = fill_to_limit(
      yaml_with(kGoodK), [](int i) { return name_of(i) + ": 1\n"; }, "");
  EXPECT_MENTIONS(parse_error(keys), "more than 20000 YAML nodes");
  const std::string lists = fill_to_limit(
      yaml_with(kGoodK, "other: ["), [](int) { return "[], "; }, "1]\n");
  EXPECT_MENTIONS(parse_error(lists), "more than 20000 YAML nodes");
  const std::string json = json_with("");
  const std::string json_keys = fill_to_limit(
      json.substr(0, json.size() - 1), [](int i) { return ", \"" + name_of(i) + "\": 1"; }, "}");
  EXPECT_MENTIONS(parse_error(json_keys), "more than 20000 JSON values and keys");
  const std::string arrays = fill_to_limit(
      json.substr(0, json.size() - 1) + ", \"other\": [", [](int) { return "[],"; }, "1]}");
  EXPECT_MENTIONS(parse_error(arrays), "more than 20000 JSON values and keys");
  // A calibration with 15,000 values in an entry that is skipped (the image points of 140
  // views of a 9x6 board) is read in every format.
  std::string numbers = "0.5";
  for (int i = 1; i < 15000; ++i) numbers += ", 0.5";
  EXPECT_EQ(parse_error(yaml_with(kGoodK, "image_points: [ " + numbers + " ]\n")), "");
  EXPECT_EQ(parse_error(json_with(", \"image_points\": [" + numbers + "]")), "");
  EXPECT_EQ(parse_error(xml_with("<image_points><data>" + numbers + "</data></image_points>\n")), "");
}

TEST(CameraFile, YamlDirectivesAndLongNumbersAreBounded) {
  // libyaml checks each %TAG directive against all before it (60,000 in 1 MiB took 9 s).
  const std::string tags = fill_to_limit(
      "%YAML:1.0\n", [](int i) { return "%TAG !" + name_of(i) + "! tag:x:\n"; }, yaml_with(kGoodK).substr(10));
  EXPECT_MENTIONS(error_within([&] { Camera::parse(tags, "tags.yml"); }),
                  "tags.yml: it has more than 8 lines starting with '%' (YAML directives)");

  // A number of a million digits: strtod's time, refused from its length.
  const std::string digits(1 << 19, '1');
  EXPECT_MENTIONS(parse_error(json_with(", \"other\": 0." + digits)), "it has a number of more than 64 characters");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, "image_width: " + digits + "\n")),
                  "'image_width' is '1111111111111111111111111111111111111111...', expected a number (of at most 64 "
                  "characters)");
  EXPECT_MENTIONS(parse_error(xml_with("<image_width>" + digits + "</image_width>")),
                  "expected a number (of at most 64 characters)");
}

TEST(CameraFile, OnlyRegularFilesAreOpened) {
  // A FIFO without a writer blocked the open forever; a device is not opened at all.
  const std::string dir = testing::TempDir() + "/calibration-kinds";
  ::mkdir(dir.c_str(), 0700);
  const std::string fifo = dir + "/fifo.yml", loop = dir + "/loop.yml", dangling = dir + "/dangling.yml";
  std::remove(fifo.c_str()), std::remove(loop.c_str()), std::remove(dangling.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  ASSERT_EQ(::symlink(loop.c_str(), loop.c_str()), 0);
  ASSERT_EQ(::symlink((dir + "/none.yml").c_str(), dangling.c_str()), 0);
  const std::string name = "calibration file '" + fifo + "'";
  EXPECT_MENTIONS(error_within([&] { Camera::load(fifo); }),
                  name + " cannot be opened: it is a FIFO, expected a regular file");
  EXPECT_MENTIONS(error_within([&] { Camera::load(dir); }), "cannot be opened: it is a directory");
  EXPECT_MENTIONS(error_within([] { Camera::load("/dev/zero"); }),
                  "calibration file '/dev/zero' cannot be opened: it is a character device");
  EXPECT_MENTIONS(error_within([&] { Camera::load(loop); }), "cannot be opened: it is a symbolic link loop");
  EXPECT_MENTIONS(error_within([&] { Camera::load(dangling); }), "is a symbolic link to a file that does not exist");
  EXPECT_MENTIONS(error_within([&] { Camera::load(dir + "/none.yml"); }), "cannot be opened: it does not exist");
  std::remove(fifo.c_str()), std::remove(loop.c_str()), std::remove(dangling.c_str()), ::rmdir(dir.c_str());
}

TEST(CameraFile, SizeLimit) {
  // 1 MiB at most, even when all but the first bytes are a comment.
  std::string big = yaml_with(kGoodK, "# ");
  big.resize((1 << 20) + 1, 'x');
  const std::string path = write_temp("big.yml", big);
  std::string e = load_error(path);
  EXPECT_MENTIONS(e, "big.yml");
  EXPECT_MENTIONS(e, "larger than the 1048576 bytes (1 MiB)");
  EXPECT_MENTIONS(parse_error(big), "more than the 1048576 (1 MiB)");
  big.resize(1 << 20);  // exactly 1 MiB is fine
  EXPECT_NO_THROW(Camera::load(write_temp("big.yml", big)));
  std::remove(path.c_str());
}

TEST(CameraFile, BrokenFilesOfEveryFormat) {
  // Empty, blank, not a mapping, wrong types.
  EXPECT_MENTIONS(load_error(write_temp("empty.yml", "")), "empty.yml': it is empty");
  EXPECT_MENTIONS(parse_error(" \n\t\n"), "it is empty");
  EXPECT_MENTIONS(parse_error("%YAML:1.0\n"), "it is empty");
  EXPECT_MENTIONS(load_error(testing::TempDir()), "is a directory");
  EXPECT_MENTIONS(parse_error("%YAML:1.0\n- 1\n- 2\n"), "top level is not a mapping");
  EXPECT_MENTIONS(parse_error("%YAML:2.0\ncamera_matrix: 1\n"), "not an OpenCV YAML header");
  EXPECT_MENTIONS(parse_error("[1, 2]"), "top level is not a mapping");
  EXPECT_MENTIONS(parse_error("camera_matrix: 5"), "'camera_matrix' is a single value, expected an OpenCV matrix");
  EXPECT_MENTIONS(parse_error("camera_matrix: [1, 2, 3]"), "'camera_matrix' is a list");
  EXPECT_MENTIONS(parse_error("camera_matrix: !!opencv-nd-matrix {rows: 3}"), "has the type");
  EXPECT_MENTIONS(parse_error("camera_matrix: {rows: 3, cols: 3, dt: d}"), "has no 'data'");
  EXPECT_MENTIONS(parse_error("camera_matrix: {rows: three, cols: 3, dt: d, data: []}"),
                  "'camera_matrix' rows is 'three', expected a number");
  EXPECT_MENTIONS(parse_error("camera_matrix: {rows: 3, cols: 3, dt: 3d, data: []}"), "dt is '3d', expected d or f");
  EXPECT_MENTIONS(parse_error("camera_matrix: {rows: 3, cols: 3, dt: d, data: {a: 1}}"), "data is a mapping");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, "camera_matrix: 1\n")), "'camera_matrix' appears twice");
  EXPECT_MENTIONS(parse_error(yaml_with(kGoodK, "---\nb: 1\n")), "more than one YAML document");
  EXPECT_MENTIONS(parse_error("{\"camera_matrix\": {\"type_id\": 5}}"), "'type_id' is not a string");
  EXPECT_MENTIONS(parse_error("{\"camera_matrix\": {\"type_id\": \"opencv-matrix\", \"rows\": \"3\", \"cols\": 3, "
                              "\"dt\": \"d\", \"data\": []}}"),
                  "rows is '3', expected a number");
  EXPECT_MENTIONS(parse_error("{\"camera_matrix\": 1} x"), "not valid JSON");
  EXPECT_MENTIONS(parse_error("<?xml version=\"1.0\"?><storage></storage>"),
                  "root element is <storage>, expected <opencv_storage>");
  EXPECT_MENTIONS(parse_error("<opencv_storage><camera_matrix>1 <a/></camera_matrix></opencv_storage>"),
                  "mixes text and elements");

  // Every truncation of a valid file of each format is an error or a valid camera.
  for (const char* ext : {"yml", "xml", "json"}) {
    Camera c = Camera::pinhole(500, 510, 320, 240, 640, 480);
    c.distortion = {0.1, -0.05, 0.001, 0.002, 0.01};
    const std::string path = testing::TempDir() + "/whole." + ext;
    c.save(path);
    std::ifstream in(path, std::ios::binary);
    const std::string whole((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    int errors = 0;
    for (std::size_t n = 0; n < whole.size(); ++n) {
      try {
        const Camera t = Camera::parse(whole.substr(0, n), "truncated");
        EXPECT_NO_THROW(t.validate());
      } catch (const std::runtime_error& e) {
        ++errors;
        EXPECT_EQ(std::string(e.what()).rfind("truncated: ", 0), 0u) << e.what();
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
      }
    }
    EXPECT_GT(errors, int(whole.size()) / 2) << ext;
    // Cut in the middle of the camera matrix's data.
    const std::size_t cut = whole.find("data") + 12;
    EXPECT_NE(parse_error(whole.substr(0, cut)), "") << ext;
  }

  // Binary garbage: with NUL bytes, and without.
  std::mt19937 random(7);
  for (int round = 0; round < 200; ++round) {
    std::string bytes(1 + random() % 600, '\0');
    for (char& b : bytes) b = char(random());
    if (round % 2)
      for (char& b : bytes) b = b ? b : 'x';
    const std::string e = parse_error(bytes);
    EXPECT_EQ(e.rfind("inline: ", 0), 0u) << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
  const std::string png = "\x89PNG\r\n\x1a\n" + std::string("\0\0\0\rIHDR", 8);
  EXPECT_MENTIONS(parse_error(png), "NUL byte at offset 8");
  // Unprintable bytes from the file are escaped in messages.
  EXPECT_MENTIONS(parse_error(json_with(", \"image_width\": \"\\u001b[31m\"")),
                  "'image_width' is '\\x1b[31m', expected a number");
}

TEST(CameraFile, ProgrammaticCamerasGetTheSameChecks) {
  EXPECT_THROW(Camera::pinhole(1e-300, 600, 319.5, 239.5).validate(), std::invalid_argument);
  EXPECT_THROW(Camera::pinhole(600, 2e7, 319.5, 239.5).validate(), std::invalid_argument);
  EXPECT_THROW(Camera::pinhole(600, 600, std::nan(""), 239.5).validate(), std::invalid_argument);
  EXPECT_THROW(Camera::pinhole(600, 600, 319.5, 239.5, 1 << 20, 480).validate(), std::invalid_argument);
  EXPECT_THROW(Camera::pinhole(600, 600, 319.5, 239.5, -1, 480).validate(), std::invalid_argument);
  Camera c = Camera::pinhole(600, 600, 319.5, 239.5, 640, 480);
  EXPECT_NO_THROW(c.validate());
  c.distortion = {0.1, 0.2, 0, 0, 0, 0};
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c.distortion = {0.1, 0.2, 0, 1e5};
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c.distortion = {0.1, 0.2, 0, 0, 0, 0.3, 0.1, 0.01};
  EXPECT_NO_THROW(c.validate());
  EXPECT_NO_THROW(Camera::default_for(7680, 4320).validate());
}

// ---------------------------------------------------------------------------
// Everything OpenCV writes for a calibration loads.

TEST(CameraFile, RoundTripsThroughSaveInEveryFormat) {
  for (const char* ext : {"yml", "yaml", "xml", "json"}) {
    for (const std::vector<double>& distortion : {std::vector<double>{},
                                                  {0.1, -0.05, 0.001, 0.002},
                                                  {0.1, -0.05, 0.001, 0.002, 0.01},
                                                  {0.1, -0.05, 0.001, 0.002, 0.01, 0.3, -0.02, 1e-7}}) {
      Camera c = Camera::pinhole(628.158, 628.156, 324.099, 260.908, 640, 480);
      c.distortion = distortion;
      const std::string path = testing::TempDir() + "/roundtrip." + ext;
      c.save(path);
      const Camera d = Camera::load(path);
      EXPECT_TRUE(d.calibrated);
      EXPECT_EQ(d.fx, c.fx) << ext;
      EXPECT_EQ(d.fy, c.fy) << ext;
      EXPECT_EQ(d.cx, c.cx) << ext;
      EXPECT_EQ(d.cy, c.cy) << ext;
      EXPECT_EQ(d.width, 640) << ext;
      EXPECT_EQ(d.height, 480) << ext;
      if (distortion.empty())
        EXPECT_FALSE(d.has_distortion()) << ext;
      else
        EXPECT_EQ(d.distortion, c.distortion) << ext;
    }
    // No frame size: it stays unknown.
    const std::string path = testing::TempDir() + "/nosize." + ext;
    Camera::pinhole(500, 500, 1, 2).save(path);
    EXPECT_EQ(Camera::load(path).width, 0);
  }
}

TEST(CameraFile, LoadsWhatOpenCvWritesDirectly) {
  // dt f and d; distortion as 1xN and Nx1; the GStreamer keys; data over several lines.
  for (const char* ext : {"yml", "xml", "json"}) {
    for (const int depth : {CV_32F, CV_64F}) {
      for (const bool column : {false, true}) {
        for (const bool gst_keys : {false, true}) {
          const cv::Matx33d k(1234.5678901, 0, 640.12345678, 0, 1234.9876543, 359.87654321, 0, 0, 1);
          cv::Mat km, dm;
          cv::Mat(k).convertTo(km, depth);
          cv::Mat(cv::Matx<double, 1, 8>(-0.25, 0.0812345678, 0.00123, -0.00045, 0.0101, 0.02, -0.003, 0.0004))
              .convertTo(dm, depth);
          if (column) dm = dm.t();
          const std::string path = testing::TempDir() + "/opencv." + ext;
          {
            cv::FileStorage fs(path, cv::FileStorage::WRITE);
            fs << "calibration_time"
               << "Tue 25 Nov 2026";
            fs << "nframes" << 20 << "image_width" << 1280 << "image_height" << 720;
            fs << (gst_keys ? "cameraMatrix" : "camera_matrix") << km;
            fs << (gst_keys ? "distCoeffs" : "distortion_coefficients") << dm;
            fs << "avg_reprojection_error" << 0.31;
            fs << "extrinsic_parameters" << cv::Mat(20, 6, CV_64F, cv::Scalar(0.5));
            fs << "image_points" << cv::Mat(54, 20, CV_32FC2, cv::Scalar(1.5, 2.5));
          }
          const Camera c = Camera::load(path);
          const std::string what = std::string(ext) + (depth == CV_32F ? " f" : " d") + (column ? " Nx1" : " 1xN") +
                                   (gst_keys ? " gst" : "");
          auto as_written = [&](double v) { return depth == CV_32F ? double(float(v)) : v; };
          EXPECT_EQ(c.fx, as_written(k(0, 0))) << what;
          EXPECT_EQ(c.fy, as_written(k(1, 1))) << what;
          EXPECT_EQ(c.cx, as_written(k(0, 2))) << what;
          EXPECT_EQ(c.cy, as_written(k(1, 2))) << what;
          EXPECT_EQ(c.width, 1280) << what;
          ASSERT_EQ(c.distortion.size(), 8u) << what;
          EXPECT_EQ(c.distortion[1], as_written(0.0812345678)) << what;
          EXPECT_EQ(c.distortion[7], as_written(0.0004)) << what;
        }
      }
    }
  }
}

TEST(CameraFile, LoadsOpenCvsOwnSampleCalibration) {
  // opencv-doc's output of OpenCV's calibration sample: "%YAML:1.0" then "---", extra
  // entries (matrices of other sizes, dt f) that are skipped.
  const std::string sample = "/usr/share/doc/opencv-doc/examples/data/left_intrinsics.yml";
  if (!std::ifstream(sample)) GTEST_SKIP() << sample << " is not installed (opencv-doc)";
  const Camera c = Camera::load(sample);
  EXPECT_DOUBLE_EQ(c.fx, 5.3591573396163199e+02);
  EXPECT_DOUBLE_EQ(c.cy, 2.3557082909788173e+02);
  EXPECT_EQ(c.width, 640);
  ASSERT_EQ(c.distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(c.distortion[4], 2.3839153080878486e-01);
}

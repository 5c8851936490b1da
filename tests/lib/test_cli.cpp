// SPDX-License-Identifier: LGPL-2.1-or-later
// The `lftag` tool as scripts use it: exit status, messages, files.
#include <cstdio>
#include <fstream>
#include <memory>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "detection_json.hpp"  // src/io: the JSON of one detection, shared by every output
#include "tunables.hpp"        // src/io: the detector options' table

namespace {

struct CliResult {
  int status;
  std::string output;  // stdout and stderr
};

CliResult run(const std::string& args) {
  const std::string cmd = std::string(LFTAG_CLI) + " " + args + " 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  std::string out;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe.get())) > 0) out.append(buf, n);
  const int status = pclose(pipe.release());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

const std::string kTmp = testing::TempDir();

// `lftag ARGS` exits with `status`, and its output contains `says`.
testing::AssertionResult exits_saying(const std::string& args, int status, const std::string& says) {
  const CliResult r = run(args);
  if (r.status == status && r.output.find(says) != std::string::npos) return testing::AssertionSuccess();
  return testing::AssertionFailure() << "lftag " << args << "\nexited " << r.status << " (expected " << status
                                     << "), saying:\n"
                                     << r.output << "(expected it to say '" << says << "')";
}

}  // namespace

TEST(Cli, GenerateWritesEveryFormat) {
  for (const char* ext : {"svg", "pdf", "png"}) {
    const std::string out = kTmp + "/cli." + ext;
    std::remove(out.c_str());
    const CliResult r = run("generate --family 4x4 --id 0xabc --size 5cm --output " + out);
    EXPECT_EQ(r.status, 0) << r.output;
    EXPECT_TRUE(std::ifstream(out).good()) << out;
  }
  const CliResult sheet =
      run("generate --family 3x3 --id 0-29 --size 40mm --paper letter --output " + kTmp + "/sheet.pdf");
  EXPECT_EQ(sheet.status, 0) << sheet.output;
  EXPECT_NE(sheet.output.find("30 markers"), std::string::npos) << sheet.output;
}

TEST(Cli, GenerateRejectsBadInputWithAMessage) {
  // A mistake in the options exits 2, as in detect and annotate (an unknown family once
  // exited 1); a file that cannot be written, 1.
  EXPECT_TRUE(exits_saying("generate --family 9x9 --id 1 --output " + kTmp + "/x.svg", 2, "unknown family '9x9'"));
  EXPECT_TRUE(
      exits_saying("generate --family 3x3 --id 16384 --output " + kTmp + "/x.svg", 2, "out of range for family 3x3"));
  EXPECT_TRUE(exits_saying("generate --family 3x3 --id 12 --output /nonexistent-dir/x.svg", 1,
                           "cannot write '/nonexistent-dir/x.svg'"));
  EXPECT_TRUE(exits_saying("generate --family 3x3 --id twelve --output " + kTmp + "/x.svg", 2, "not a decimal number"));
  EXPECT_TRUE(
      exits_saying("generate --family 3x3 --id 1 --size 3furlongs --output " + kTmp + "/x.svg", 2, "unknown unit"));
  EXPECT_TRUE(
      exits_saying("generate --family 3x3 --id 1-4 --paper a5 --output " + kTmp + "/x.pdf", 2, "unknown paper 'a5'"));
  EXPECT_TRUE(exits_saying("generate --family 3x3 --output " + kTmp + "/x.svg", 2, "--id"));
}

// A size without a unit is refused, naming the units, and nothing is written: "--size 0.1"
// once made a 2x2 px PNG (millimetres, where --tag-size is in metres).
TEST(Cli, GenerateRequiresASizeUnit) {
  for (const char* size : {"0.1", "100"}) {
    const std::string out = kTmp + "/nounit.png";
    std::remove(out.c_str());
    const CliResult r = run(std::string("generate --family 3x3 --id 1 --size '") + size + "' --output " + out);
    EXPECT_EQ(r.status, 2) << size << ": " << r.output;
    EXPECT_NE(r.output.find("no unit"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("mm, cm, m or in"), std::string::npos) << r.output;
    EXPECT_FALSE(std::ifstream(out).good()) << size;
  }
  EXPECT_EQ(run("generate --family 3x3 --id 1 --size 0.1m --output " + kTmp + "/unit.png").status, 0);
}

// Id lists take spaces as family lists do; a negative or empty id says what is wrong.
TEST(Cli, GenerateIdListsSayWhatIsWrong) {
  EXPECT_TRUE(exits_saying("generate --family 3x3 --id '1, 2' --output " + kTmp + "/spaced.pdf", 0, "wrote 2 markers"));
  EXPECT_TRUE(
      exits_saying("generate --family 3x3 --id ' 0 - 3 , 7' --output " + kTmp + "/spaced.pdf", 0, "wrote 5 markers"));
  CliResult r = run("generate --family 3x3 --id -1 --output " + kTmp + "/x.svg");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("id '-1' is negative"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("''"), std::string::npos) << r.output;
  for (const char* bad : {"1,,2", "1,"}) {
    r = run(std::string("generate --family 3x3 --id ") + bad + " --output " + kTmp + "/x.svg");
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("empty item"), std::string::npos) << bad << ": " << r.output;
  }
  EXPECT_TRUE(exits_saying("generate --family 3x3 --id 5- --output " + kTmp + "/x.svg", 2, "no last id"));
}

TEST(Cli, GenerateRejectsNumbersItCannotUse) {
  // --dpi 1e9 once reached a float-to-int conversion and a misleading message: every number
  // is an option error (exit 2) naming the option, and a PNG too large for cairo is refused
  // before anything is drawn, leaving no file.
  for (const char* bad : {"--dpi 1e9", "--dpi nan", "--dpi 0.5", "--size 1e300", "--size nan", "--size 1e-300mm",
                          "--size -3", "--margin 1e300", "--margin nan", "--margin -1"}) {
    const CliResult r = run(std::string("generate --family 3x3 --id 1 ") + bad + " --output " + kTmp + "/bad.png");
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(std::string(bad).substr(0, std::string(bad).find(' '))), std::string::npos) << r.output;
  }
  const std::string huge = kTmp + "/huge.png";
  std::remove(huge.c_str());
  EXPECT_TRUE(exits_saying("generate --family 3x3 --id 1 --size 3m --dpi 1000 --output " + huge, 1, "more than 32767"));
  EXPECT_FALSE(std::ifstream(huge).good());
  // The extremes of the ranges work where the file can hold them.
  EXPECT_EQ(
      run("generate --family 3x3 --id 1 --size 0.1mm --dpi 1 --margin 100 --output " + kTmp + "/small.png").status, 0);
  EXPECT_EQ(run("generate --family 3x3 --id 1 --size 100m --output " + kTmp + "/big.pdf").status, 0);
}

TEST(Cli, RenderWritesImageAndTruth) {
  const std::string png = kTmp + "/scene.png";
  const CliResult r = run(
      "render --family 8x8 --id 0x123456789abcdef0123456789abcdef --distance 3 --tilt 30 --noise 2 --output " + png);
  ASSERT_EQ(r.status, 0) << r.output;
  const cv::Mat image = cv::imread(png, cv::IMREAD_GRAYSCALE);
  EXPECT_EQ(image.cols, 640);
  EXPECT_EQ(image.rows, 480);
  std::ifstream in(kTmp + "/scene.json");
  const nlohmann::json truth = nlohmann::json::parse(in);
  ASSERT_EQ(truth["markers"].size(), 1u);
  const auto& m = truth["markers"][0];
  EXPECT_EQ(m["family"], "8x8");
  EXPECT_EQ(m["id"], "1512366075204170929049582354406559215");  // over 53 bits: a decimal string
  EXPECT_EQ(m["keypoints"].size(), 4u);
  EXPECT_EQ(m["centers"].size(), 64u);
  EXPECT_TRUE(m["fully_visible"].get<bool>());
}

TEST(Cli, RenderRejectsNumbersItCannotUse) {
  // NaN, infinities and denormal focal lengths once crashed the renderer (NaN coordinates
  // passed its range checks): now they are option errors naming the option.
  for (const char* bad : {"--fx 1e-300", "--fx nan", "--fy inf", "--distance inf", "--tag-size 1e308", "--noise nan",
                          "--roll nan", "--x 1e300"}) {
    const CliResult r = run(std::string("render ") + bad + " --output " + kTmp + "/bad.png");
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(std::string(bad).substr(0, std::string(bad).find(' '))), std::string::npos) << r.output;
  }
  // The extremes of the ranges render.
  EXPECT_EQ(run("render --fx 0.001 --fy 0.001 --output " + kTmp + "/tiny.png").status, 0);
}

TEST(Cli, RenderRejectsBadInput) {
  CliResult r = run("render --family 3x3 --id 99999 --output " + kTmp + "/x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("out of range"), std::string::npos) << r.output;
  r = run("render --calibration /nonexistent.yml --output " + kTmp + "/x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("/nonexistent.yml"), std::string::npos) << r.output;
  r = run("render --output /nonexistent-dir/x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("cannot write"), std::string::npos) << r.output;
}

std::vector<nlohmann::json> json_lines(const std::string& text) {
  std::vector<nlohmann::json> out;
  std::size_t start = 0;
  while (start < text.size()) {
    const std::size_t end = text.find('\n', start);
    const std::string line = text.substr(start, end - start);
    if (!line.empty() && line[0] == '{') out.push_back(nlohmann::json::parse(line));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return out;
}

TEST(Cli, DetectPrintsOneJsonObjectPerImageInOrder) {
  const std::string a = kTmp + "/det_a.png", b = kTmp + "/det_b.png";
  ASSERT_EQ(run("render --family 4x4 --id 0xabcdef --distance 2 --tilt 20 --output " + a).status, 0);
  ASSERT_EQ(run("render --family 8x8 --id 21267647932558653966460912964485513215 --distance 2.5 --output " + b).status,
            0);
  const CliResult r = run("detect --family 3x3,4x4,8x8 --fx 320 --cx 319.5 --cy 239.5 --tag-size 1 " + a + " " + b);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto lines = json_lines(r.output);
  ASSERT_EQ(lines.size(), 2u) << r.output;
  EXPECT_EQ(lines[0]["image"], a);
  EXPECT_EQ(lines[0]["width"], 640);
  EXPECT_GT(lines[0]["time_ms"].get<double>(), 0);
  ASSERT_EQ(lines[0]["detections"].size(), 1u);
  const auto& d = lines[0]["detections"][0];
  EXPECT_EQ(d["family"], "4x4");
  EXPECT_EQ(d["id"], 0xabcdef);
  EXPECT_EQ(d["keypoints"].size(), 4u);
  EXPECT_EQ(d["center"].size(), 2u);
  EXPECT_NEAR(d["pose"]["tvec"][2].get<double>(), 2.0, 0.02);  // calibrated with the render's camera
  EXPECT_TRUE(d["pose"]["calibrated"].get<bool>());
  // Both solutions of the planar pose: the other fits worse by the ratio.
  EXPECT_GE(d["pose"]["ambiguity_ratio"].get<double>(), 1);
  EXPECT_EQ(d["pose"]["alternative"]["tvec"].size(), 3u);
  EXPECT_NEAR(d["pose"]["alternative"]["reprojection_error"].get<double>(),
              d["pose"]["ambiguity_ratio"].get<double>() * d["reprojection_error"].get<double>(), 1e-9);
  ASSERT_EQ(lines[1]["detections"].size(), 1u);
  EXPECT_EQ(lines[1]["detections"][0]["id"], "21267647932558653966460912964485513215");  // a string over 53 bits
}

TEST(Cli, DetectReportsUnreadableImagesAndGoesOn) {
  const std::string good = kTmp + "/det_good.png", junk = kTmp + "/det_junk.png";
  ASSERT_EQ(run("render --id 5 --output " + good).status, 0);
  { std::ofstream(junk) << "not an image"; }
  // A PNG whose header declares 400 megapixels (the data is a 16 x 16 image's) is refused
  // before decoding, with the limit in the message.
  const std::string huge = kTmp + "/det_huge.png";
  ASSERT_TRUE(cv::imwrite(huge, cv::Mat(16, 16, CV_8U, cv::Scalar(0))));
  {
    std::fstream f(huge, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(16);
    const char size[8] = {0, 0, 0x4e, 0x20, 0, 0, 0x4e, 0x20};  // 20000 x 20000, big-endian
    f.write(size, 8);
  }
  const CliResult r = run("detect /nonexistent.png " + junk + " " + huge + " " + good);
  EXPECT_EQ(r.status, 1);
  const auto lines = json_lines(r.output);
  ASSERT_EQ(lines.size(), 4u) << r.output;
  EXPECT_TRUE(lines[0].contains("error"));
  EXPECT_TRUE(lines[1].contains("error"));
  EXPECT_NE(lines[2].value("error", "").find("20000x20000 pixels, more than the limit"), std::string::npos) << r.output;
  EXPECT_EQ(lines[3]["detections"].size(), 1u);
  EXPECT_FALSE(lines[3]["detections"][0]["pose"]["calibrated"].get<bool>());  // the default camera
  EXPECT_EQ(r.output.find("WARN"), std::string::npos) << r.output;
}

TEST(Cli, DetectRefusesAJpegWhoseFillBytesHideItsSize) {
  // SOI, 4,100 fill bytes, then a frame of 32768 x 32768: refused from its header (the
  // header walk once stopped at 4,096 fill bytes, and OpenCV decoded 1 GB).
  const std::string fill = kTmp + "/det_fill.jpg";
  {
    std::ofstream f(fill, std::ios::binary);
    f << "\xFF\xD8" << std::string(4100, '\xFF')
      << std::string("\xFF\xC0\x00\x0B\x08\x80\x00\x80\x00\x01\x01\x11\x00", 13);
  }
  const CliResult r = run("detect " + fill);
  EXPECT_EQ(r.status, 1);
  const auto lines = json_lines(r.output);
  ASSERT_EQ(lines.size(), 1u) << r.output;
  EXPECT_NE(lines[0].value("error", "").find("is 32768x32768 pixels, more than the limit of 100000000"),
            std::string::npos)
      << r.output;
}

TEST(Cli, DetectStatsAndDebugImages) {
  const std::string img = kTmp + "/det_stats.png", dir = kTmp + "/det_debug";
  ASSERT_EQ(run("render --id 77 --output " + img).status, 0);
  const CliResult r = run("detect --stats --debug-dir " + dir + " " + img);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto lines = json_lines(r.output);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0]["stats"]["funnel"]["decoded"], 1);
  EXPECT_GT(lines[0]["stats"]["time_ms"]["total"].get<double>(), 0);
  for (const char* stage : {"threshold", "candidates", "keypoints", "hypotheses", "final"})
    EXPECT_FALSE(cv::imread(dir + "/det_stats-" + stage + ".png").empty()) << stage;
}

// `lftag detect --why --stats --family 3x3` of a scene rendered on a 6-unit margin into
// `image`: its one line of JSON (empty when it is not one line).
nlohmann::json detect_why(const std::string& scene_json, const std::string& image) {
  const std::string scene = image + ".json";
  std::ofstream(scene) << scene_json;
  EXPECT_EQ(run("render --margin 6 --scene " + scene + " --output " + image).status, 0);
  // Without the deadline: the sanitizer build can take longer than its 20 ms over the
  // second look these tests are about.
  const CliResult r = run("detect --why --stats --deadline 0 --family 3x3 " + image);
  EXPECT_EQ(r.status, 0) << r.output;
  const auto lines = json_lines(r.output);
  EXPECT_EQ(lines.size(), 1u) << r.output;
  return lines.size() == 1 ? lines[0] : nlohmann::json::object();
}

TEST(Cli, DetectWhyNamesTheStageThatStoppedEachCandidate) {
  // A far 3x3 (13 px) on a white margin, found by the second look, beside a steeply
  // tilted one: --why lists every candidate with its stage.
  const std::string img = kTmp + "/why.png";
  const nlohmann::json o = detect_why(R"({"markers": [
    {"family": "3x3", "id": 6789, "tag_size": 1, "tvec": [-6, 0, 26], "roll": 45},
    {"family": "3x3", "id": 12345, "tag_size": 1, "tvec": [1, 0, 3], "tilt": 86}]})",
                                      img);
  ASSERT_EQ(o["detections"].size(), 1u) << o;
  EXPECT_EQ(o["detections"][0]["id"], 6789);
  EXPECT_GE(o["stats"]["funnel"]["second_looks"].get<int>(), 1);
  EXPECT_EQ(o["stats"]["funnel"]["second_look_found"], 1);
  ASSERT_FALSE(o["candidates"].empty());
  const std::set<std::string> known = {"area",   "geometry", "angle", "collinearity", "resolution", "decoding",
                                       "margin", "ink",      "pose",  "duplicate",    "detected"};
  int detected = 0;
  for (const auto& c : o["candidates"]) {
    EXPECT_EQ(known.count(c["stage"].get<std::string>()), 1u) << c;
    EXPECT_EQ(c["centroids"].size(), 9u);
    if (c["stage"] != "detected") continue;
    ++detected;
    EXPECT_TRUE(c["second_look"].get<bool>());
    EXPECT_EQ(c["reading"], 6789);
    // Read by its blobs: the noise margin it was accepted with, as the detection reports it.
    EXPECT_GE(c["noise_margin"].get<double>(), 2.0) << c;
    EXPECT_EQ(c["noise_margin"], o["detections"][0]["noise_margin"]) << c;
  }
  EXPECT_EQ(detected, 1);
  // Without --why there are no candidates.
  EXPECT_FALSE(json_lines(run("detect " + img).output)[0].contains("candidates"));
}

TEST(Cli, DetectWhyListsTheOutlineReads) {
  // A 3x3 at 29 m (11 px) on a white margin, whose squares no binary image separates: no
  // candidate, but --why lists the outline reads of its second look, the one that found
  // it with its reading, and the stage that stopped the others.
  const std::string img = kTmp + "/why-outline.png";
  const nlohmann::json o = detect_why(
      R"({"markers": [{"family": "3x3", "id": 6789, "tag_size": 1, "tvec": [-6, 0, 29], "roll": 30}]})", img);
  ASSERT_EQ(o["detections"].size(), 1u) << o;
  EXPECT_EQ(o["detections"][0]["id"], 6789);
  EXPECT_TRUE(o["detections"][0]["from_outline"].get<bool>());
  ASSERT_EQ(o["outline_reads"].size(), o["stats"]["funnel"]["outline_reads"].get<std::size_t>());
  const std::set<std::string> known = {"budget",     "deadline", "alignment", "structure", "contrast",  "baselines",
                                       "resolution", "margin",   "marker",    "pose",      "duplicate", "detected"};
  int detected = 0;
  for (const auto& c : o["outline_reads"]) {
    EXPECT_EQ(known.count(c["stage"].get<std::string>()), 1u) << c;
    EXPECT_EQ(c["outline"].size(), 4u);
    EXPECT_EQ(c["family"], "3x3");
    EXPECT_GE(c["defocus"].get<double>(), 0) << c;
    if (c["stage"] != "detected") continue;
    ++detected;
    EXPECT_EQ(c["reading"], 6789);
    EXPECT_GE(c["correlation"].get<double>(), 0.75);
    EXPECT_GE(c["margin"].get<double>(), 0.03);
    // An outline reading reports its noise margin (not bound) as the detection does.
    EXPECT_GT(c["noise_margin"].get<double>(), 0) << c;
    EXPECT_EQ(c["noise_margin"], o["detections"][0]["noise_margin"]) << c;
  }
  EXPECT_EQ(detected, 1);
  EXPECT_FALSE(json_lines(run("detect " + img).output)[0].contains("outline_reads"));
}

TEST(Cli, DetectRejectsBadConfiguration) {
  CliResult r = run("detect --family 3x4 x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("unknown family '3x4'"), std::string::npos) << r.output;
  r = run("detect --calibration /nonexistent.yml x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("/nonexistent.yml"), std::string::npos) << r.output;
  // A hostile calibration file (OpenCV's parser crashed on a NUL byte) is one line naming it.
  const std::string hostile = kTmp + "/hostile.xml";
  std::ofstream(hostile, std::ios::binary) << std::string("<?xml version=\"1.0\"?>\n<opencv_storage a=\"\0\">", 44);
  r = run("detect --calibration " + hostile + " x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.output, "lftag detect: calibration file '" + hostile +
                          "': it has a NUL byte at offset 41, expected text (OpenCV YAML, XML or JSON)\n");
  r = run("detect --threshold-window 1 x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("--threshold-window"), std::string::npos) << r.output;
  // Numbers that are not finite or not representable are option errors (exit 2) naming
  // the option, never ignored or left to fail per image.
  for (const char* bad :
       {"--fx nan", "--fx -5", "--fx 1e-300", "--fy inf", "--cx nan", "--tag-size 1e308", "--tag-size 0"}) {
    r = run(std::string("detect --fx 300 ") + bad + " x.png");
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(std::string(bad).substr(0, std::string(bad).find(' '))), std::string::npos) << r.output;
  }
  r = run("detect --cx 100 x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("need --fx"), std::string::npos) << r.output;
  r = run("detect --ids 9-3 x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("--ids"), std::string::npos) << r.output;
  r = run("detect --family 3x3 --ids 5,16384 x.png");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("16384 is not an id of any family"), std::string::npos) << r.output;
}

TEST(Cli, DetectReportsOnlyTheIdsInUse) {
  const std::string image = kTmp + "/ids.png";
  ASSERT_EQ(run("render --family 4x4 --id 777 --distance 2 --output " + image).status, 0);
  for (const auto& [ids, found] : {std::pair{"", 1}, std::pair{"1-776,778", 0}, std::pair{"5,700-800", 1}}) {
    const CliResult r = run(std::string("detect --stats ") + (*ids ? std::string("--ids ") + ids + " " : "") + image);
    ASSERT_EQ(r.status, 0) << r.output;
    const auto lines = json_lines(r.output);
    ASSERT_EQ(lines.size(), 1u) << r.output;
    EXPECT_EQ(int(lines[0]["detections"].size()), found) << ids;
    EXPECT_EQ(lines[0]["stats"]["funnel"]["unlisted"].get<int>(), 1 - found) << ids;
  }
}

TEST(Cli, CameraOptionsNotGivenAreEmptyAndZeroIsZero) {
  // A marker at the image centre (the render's camera: fx 320, 640x480, centred).
  const std::string image = kTmp + "/principal.png";
  ASSERT_EQ(run("render --family 3x3 --id 77 --distance 3 --output " + image).status, 0);
  // Without --cx and --cy the principal point is the centre; --cx 0 --cy 0 is the
  // top-left pixel, so the pose puts the marker 319.5 px right and 239.5 px down of it.
  for (const auto& [camera, cx, cy] :
       {std::tuple{"", 319.5, 239.5}, std::tuple{"--cx 0 --cy 0", 0.0, 0.0}, std::tuple{"--cy 0", 319.5, 0.0}}) {
    const CliResult r = run(std::string("detect --family 3x3 --tag-size 1 --fx 320 ") + camera + " " + image);
    ASSERT_EQ(r.status, 0) << r.output;
    const auto lines = json_lines(r.output);
    ASSERT_EQ(lines.size(), 1u) << r.output;
    ASSERT_EQ(lines[0]["detections"].size(), 1u) << r.output;
    const auto& d = lines[0]["detections"][0];
    const std::vector<double> t = d["pose"]["tvec"];
    EXPECT_NEAR(320 * t[0] / t[2] + cx, d["center"][0].get<double>(), 0.5) << camera;
    EXPECT_NEAR(320 * t[1] / t[2] + cy, d["center"][1].get<double>(), 0.5) << camera;
  }
}

TEST(Cli, HelpDocumentsTheOptions) {
  const CliResult r = run("generate --help");
  EXPECT_EQ(r.status, 0);
  for (const char* opt : {"--family", "--id", "--size", "--margin", "--dpi", "--sheet", "--paper", "--output"})
    EXPECT_NE(r.output.find(opt), std::string::npos) << opt;
  const CliResult top = run("--help");
  EXPECT_NE(top.output.find("render"), std::string::npos);
  EXPECT_NE(top.output.find("detect"), std::string::npos);
  const CliResult detect = run("detect --help");
  for (const char* opt : {"--family", "--fx", "--calibration", "--tag-size", "--stats", "--debug-dir"})
    EXPECT_NE(detect.output.find(opt), std::string::npos) << opt;
  EXPECT_NE(run("").status, 0);
}

// One row per tunable reaches one field of DetectorParams: set to its other bound, the
// parameters differ from the defaults and read it back.
TEST(Cli, EachTunableReachesTheDetectorsParameters) {
  const lftag::DetectorParams defaults = lftag::io::front_end_defaults();
  for (const lftag::io::Tunable& t : lftag::io::tunables()) {
    lftag::DetectorParams p = defaults;
    const double other = t.get(defaults) == t.max ? t.min : t.max;
    t.set(p, other);
    EXPECT_EQ(t.get(p), other) << t.name;
    EXPECT_NE(p, defaults) << t.name;
    if (p.ids_complete) {  // says something of the ids, which must then be given
      EXPECT_THROW(p.validate(), std::invalid_argument) << t.name;
      p.ids = {lftag::TagId(5)};
    }
    EXPECT_NO_THROW(p.validate()) << t.name << " at " << other;
  }
}

TEST(Cli, DetectTakesEveryTunableAsAnOption) {
  const std::string image = kTmp + "/tunables.png";
  ASSERT_EQ(run("render --family 3x3 --id 5 --distance 3 --output " + image).status, 0);
  const CliResult help = run("detect --help");
  for (const lftag::io::Tunable& t : lftag::io::tunables())
    EXPECT_NE(help.output.find(std::string("--") + t.name), std::string::npos) << t.name;
  // Options read as the element's properties are: the marker is read with any of them.
  CliResult r =
      run("detect --family 3x3 --second-look false --max-ink-ratio 3 --max-decode-error 0.001 "
          "--max-cell-residual 0.4 --min-spread-ratio 0.2 --deadline 0 " +
          image);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto lines = json_lines(r.output);
  ASSERT_EQ(lines.size(), 1u) << r.output;
  ASSERT_EQ(lines[0]["detections"].size(), 1u) << r.output;
  EXPECT_EQ(lines[0]["detections"][0]["id"], 5);
  // Out of the table's range, or not of its type: an option error naming the option.
  for (const char* bad : {"--max-ink-ratio 0.5", "--min-spread-ratio 2", "--second-look maybe", "--max-candidates 1.5",
                          "--deadline nan"}) {
    r = run(std::string("detect ") + bad + " " + image);
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(std::string(bad).substr(0, std::string(bad).find(' '))), std::string::npos) << r.output;
  }
}

TEST(Cli, TheJsonOfAPoseCarriesItsOtherSolutionOrNull) {
  lftag::Detection d;
  d.rvec = {0.1, 0.2, 0.3}, d.tvec = {0.01, 0.02, 1.5};
  d.alternative_rvec = {-0.1, 0.2, 0.3}, d.alternative_tvec = {0.01, 0.02, 1.49};
  d.reprojection_error = 0.04, d.alternative_reprojection_error = 0.05, d.ambiguity_ratio = 1.25;
  const nlohmann::json both = lftag::io::detection_json(d);
  EXPECT_EQ(both["pose"]["ambiguity_ratio"].get<double>(), 1.25);
  EXPECT_EQ(both["pose"]["alternative"]["rvec"], nlohmann::json({-0.1, 0.2, 0.3}));
  EXPECT_EQ(both["pose"]["alternative"]["tvec"], nlohmann::json({0.01, 0.02, 1.49}));
  EXPECT_EQ(both["pose"]["alternative"]["reprojection_error"].get<double>(), 0.05);
  // No second solution (ratio 0): no pose of zeros standing for one.
  d.ambiguity_ratio = 0;
  const nlohmann::json one = lftag::io::detection_json(d);
  EXPECT_EQ(one["pose"]["ambiguity_ratio"].get<double>(), 0);
  EXPECT_TRUE(one["pose"]["alternative"].is_null());
  EXPECT_EQ(one["pose"]["rvec"], nlohmann::json({0.1, 0.2, 0.3}));
}

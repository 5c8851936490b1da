// SPDX-License-Identifier: LGPL-2.1-or-later
// Printable marker files through cairo: the vector geometry for SVG and PDF, the exact
// coverage raster for single-marker PNGs, and sheets of many markers on A4 or Letter.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <sstream>
#include <stdexcept>

#include <cairo-pdf.h>
#include <cairo-svg.h>
#include <cairo.h>

#include "lftag/render.hpp"

namespace lftag {
namespace {

constexpr double kPointsPerMetre = 72.0 / 0.0254;

struct SurfaceDeleter {
  void operator()(cairo_surface_t* s) const { cairo_surface_destroy(s); }
};
struct ContextDeleter {
  void operator()(cairo_t* c) const { cairo_destroy(c); }
};
using Surface = std::unique_ptr<cairo_surface_t, SurfaceDeleter>;
using Context = std::unique_ptr<cairo_t, ContextDeleter>;

enum class Format { svg, pdf, png };

Format format_of(const std::string& path) {
  const std::size_t dot = path.rfind('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == "svg") return Format::svg;
  if (ext == "pdf") return Format::pdf;
  if (ext == "png") return Format::png;
  throw std::invalid_argument("cannot tell the format of '" + path + "': use a .svg, .pdf or .png file name");
}

void check(cairo_status_t status, const std::string& path) {
  if (status != CAIRO_STATUS_SUCCESS)
    throw std::runtime_error("cannot write '" + path + "': " + cairo_status_to_string(status));
}

// A file written under a temporary name beside its destination and renamed over it only
// when complete: a failed write leaves an existing file as it was, and no half file.
// Creating the temporary file fails early, before cairo makes anything, when the
// destination's folder cannot be written.
class PartFile {
 public:
  explicit PartFile(std::string path) : path_(std::move(path)), part_(path_ + ".part") {
    std::FILE* f = std::fopen(part_.c_str(), "wb");
    if (!f) throw std::runtime_error("cannot write '" + path_ + "': " + std::strerror(errno));
    std::fclose(f);
  }
  PartFile(const PartFile&) = delete;
  PartFile& operator=(const PartFile&) = delete;
  ~PartFile() {
    if (!done_) std::remove(part_.c_str());
  }
  const std::string& part() const { return part_; }
  void commit() {
    if (std::rename(part_.c_str(), path_.c_str()) != 0)
      throw std::runtime_error("cannot write '" + path_ + "': " + std::strerror(errno));
    done_ = true;
  }

 private:
  std::string path_, part_;
  bool done_ = false;
};

std::string size_text(double metres) {
  std::ostringstream s;
  s.precision(4);
  if (metres >= 1.0)
    s << metres << " m";
  else
    s << metres * 1000 << " mm";
  return s.str();
}

std::string caption_text(const Family& family, TagId id, double size_m) {
  return "LFTag " + family.name() + "  id " + id.to_decimal() + "  " + size_text(size_m);
}

double caption_font_pt(double marker_pt) { return std::clamp(marker_pt * 0.045, 5.0, 14.0); }

// Bounds a printer or a file can hold; past them the layout's integer sizes would overflow.
constexpr double kMinSizeM = 1e-4, kMaxSizeM = 100, kMaxMarginUnits = 100, kMinDpi = 1, kMaxDpi = 10000;
constexpr double kMaxPngSide = 32767;  // cairo's largest image surface

void validate(const PrintOptions& o) {
  if (!(o.size_m >= kMinSizeM && o.size_m <= kMaxSizeM))
    throw std::invalid_argument("the marker size must be from 0.1 mm to 100 m");
  if (!(o.margin_units >= 0 && o.margin_units <= kMaxMarginUnits))
    throw std::invalid_argument("the margin must be from 0 to 100 marker units");
  if (!(o.dpi >= kMinDpi && o.dpi <= kMaxDpi))
    throw std::invalid_argument("the resolution must be from 1 to 10000 dpi");
}

// Refuses a PNG whose side would pass cairo's limit, before anything is allocated.
void check_png_side(double side_px) {
  if (!(side_px <= kMaxPngSide))
    throw std::invalid_argument("the PNG would be " + std::to_string(std::llround(side_px)) +
                                " pixels a side, more than 32767: lower --dpi or the size");
}

// Draws the marker with its outer top-left corner at the current origin, `unit` points per unit.
void draw_marker(cairo_t* cr, const Family& family, TagId id, double unit) {
  const double s = family.side() * unit, b = 2 * unit;
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_rectangle(cr, b, b, s - 2 * b, s - 2 * b);
  cairo_fill(cr);
  cairo_set_source_rgb(cr, 0, 0, 0);
  cairo_set_fill_rule(cr, CAIRO_FILL_RULE_EVEN_ODD);
  cairo_rectangle(cr, 0, 0, s, s);
  cairo_rectangle(cr, b, b, s - 2 * b, s - 2 * b);
  cairo_fill(cr);
  cairo_set_fill_rule(cr, CAIRO_FILL_RULE_WINDING);
  for (const UnitRect& r : family.black_squares(id))
    cairo_rectangle(cr, r.x * unit, r.y * unit, r.width * unit, r.height * unit);
  cairo_fill(cr);
}

void draw_caption(cairo_t* cr, const std::string& text, double centre_x, double baseline_y, double font_pt) {
  cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, font_pt);
  cairo_text_extents_t ext;
  cairo_text_extents(cr, text.c_str(), &ext);
  cairo_set_source_rgb(cr, 0, 0, 0);
  cairo_move_to(cr, centre_x - ext.width / 2 - ext.x_bearing, baseline_y);
  cairo_show_text(cr, text.c_str());
}

// A marker's box on the page: margin, marker, margin, then the caption line.
struct Layout {
  double unit, margin, marker, width, height, font;
};

Layout layout(const Family& family, const PrintOptions& o) {
  Layout l;
  l.marker = o.size_m * kPointsPerMetre;
  l.unit = l.marker / family.side();
  l.margin = o.margin_units * l.unit;
  l.font = caption_font_pt(l.marker);
  l.width = l.marker + 2 * l.margin;
  l.height = l.width + (o.caption ? 1.8 * l.font : 0.0);
  return l;
}

void draw_boxed(cairo_t* cr, const Family& family, TagId id, const PrintOptions& o, const Layout& l) {
  cairo_save(cr);
  cairo_translate(cr, l.margin, l.margin);
  draw_marker(cr, family, id, l.unit);
  cairo_restore(cr);
  if (o.caption) draw_caption(cr, caption_text(family, id, o.size_m), l.width / 2, l.width + 1.2 * l.font, l.font);
}

Surface vector_surface(Format f, const std::string& path, double w, double h) {
  Surface s(f == Format::svg ? cairo_svg_surface_create(path.c_str(), w, h)
                             : cairo_pdf_surface_create(path.c_str(), w, h));
  check(cairo_surface_status(s.get()), path);
  return s;
}

// Writes to `file`; messages name `path`.
void write_png_marker(const std::string& file, const std::string& path, const Family& family, TagId id,
                      const PrintOptions& o) {
  const double px_per_unit = o.size_m / 0.0254 * o.dpi / family.side();
  const double font_px = caption_font_pt(o.size_m * kPointsPerMetre) * o.dpi / 72.0;
  const double caption_px = o.caption ? std::ceil(1.8 * font_px) : 0.0;
  check_png_side((family.side() + 2 * o.margin_units) * px_per_unit + caption_px + 1);
  const cv::Mat1b marker = rasterize_marker(family, id, px_per_unit, o.margin_units);
  const int caption_h = int(caption_px);
  Surface surface(cairo_image_surface_create(CAIRO_FORMAT_RGB24, marker.cols, marker.rows + caption_h));
  check(cairo_surface_status(surface.get()), path);
  cairo_surface_flush(surface.get());
  unsigned char* data = cairo_image_surface_get_data(surface.get());
  const int stride = cairo_image_surface_get_stride(surface.get());
  for (int y = 0; y < marker.rows + caption_h; ++y) {
    auto* row = reinterpret_cast<std::uint32_t*>(data + std::size_t(y) * stride);
    for (int x = 0; x < marker.cols; ++x) {
      const std::uint32_t v = y < marker.rows ? marker(y, x) : 255;
      row[x] = (v << 16) | (v << 8) | v;
    }
  }
  cairo_surface_mark_dirty(surface.get());
  if (o.caption) {
    Context cr(cairo_create(surface.get()));
    draw_caption(cr.get(), caption_text(family, id, o.size_m), marker.cols / 2.0, marker.rows + 1.2 * font_px, font_px);
  }
  check(cairo_surface_write_to_png(surface.get(), file.c_str()), path);
}

}  // namespace

void write_marker(const std::string& path, const Family& family, TagId id, const PrintOptions& options) {
  family.require(id);
  validate(options);
  const Format format = format_of(path);
  PartFile out(path);
  if (format == Format::png) {
    write_png_marker(out.part(), path, family, id, options);
  } else {
    const Layout l = layout(family, options);
    Surface surface = vector_surface(format, out.part(), l.width, l.height);
    Context cr(cairo_create(surface.get()));
    draw_boxed(cr.get(), family, id, options, l);
    cairo_show_page(cr.get());
    cr.reset();
    cairo_surface_finish(surface.get());
    check(cairo_surface_status(surface.get()), path);
  }
  out.commit();
}

Paper parse_paper(const std::string& name) {
  if (name == "a4" || name == "A4") return Paper::a4;
  if (name == "letter" || name == "Letter") return Paper::letter;
  throw std::invalid_argument("unknown paper '" + name + "': use a4 or letter");
}

int write_sheet(const std::string& path, const Family& family, const std::vector<TagId>& ids,
                const PrintOptions& options, Paper paper) {
  validate(options);
  if (ids.empty()) throw std::invalid_argument("a sheet needs at least one id");
  for (TagId id : ids) family.require(id);
  const Format format = format_of(path);
  const double page_w = (paper == Paper::a4 ? 0.210 : 0.2159) * kPointsPerMetre;
  const double page_h = (paper == Paper::a4 ? 0.297 : 0.2794) * kPointsPerMetre;
  const double page_margin = 0.010 * kPointsPerMetre, gap = 0.005 * kPointsPerMetre;
  const Layout l = layout(family, options);
  const int cols = int((page_w - 2 * page_margin + gap) / (l.width + gap));
  const int rows = int((page_h - 2 * page_margin + gap) / (l.height + gap));
  if (cols < 1 || rows < 1)
    throw std::invalid_argument("a " + size_text(options.size_m) + " marker does not fit on the page");
  const int per_page = cols * rows;
  const int pages = int((ids.size() + per_page - 1) / per_page);
  if (pages > 1 && format != Format::pdf)
    throw std::invalid_argument(std::to_string(ids.size()) + " markers need " + std::to_string(pages) +
                                " pages: write a .pdf, or choose fewer ids or a smaller size");
  PartFile out(path);
  // Centre the grid actually used on the page.
  const int used_cols = std::min<int>(cols, int(ids.size()));
  const int used_rows = std::min<int>(rows, int((ids.size() + used_cols - 1) / used_cols));
  const double x0 = (page_w - (used_cols * l.width + (used_cols - 1) * gap)) / 2;
  const double y0 = (page_h - (used_rows * l.height + (used_rows - 1) * gap)) / 2;

  const double px_per_pt = options.dpi / 72.0;
  if (format == Format::png) check_png_side(page_h * px_per_pt);
  Surface surface =
      format == Format::png
          ? Surface(cairo_image_surface_create(CAIRO_FORMAT_RGB24, int(std::ceil(page_w * px_per_pt - 1e-6)),
                                               int(std::ceil(page_h * px_per_pt - 1e-6))))
          : vector_surface(format, out.part(), page_w, page_h);
  check(cairo_surface_status(surface.get()), path);
  Context cr(cairo_create(surface.get()));
  if (format == Format::png) cairo_scale(cr.get(), px_per_pt, px_per_pt);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const int slot = int(i % per_page);
    if (slot == 0) {
      if (i > 0) cairo_show_page(cr.get());
      cairo_set_source_rgb(cr.get(), 1, 1, 1);
      cairo_paint(cr.get());
    }
    cairo_save(cr.get());
    cairo_translate(cr.get(), x0 + (slot % cols) * (l.width + gap), y0 + (slot / cols) * (l.height + gap));
    draw_boxed(cr.get(), family, ids[i], options, l);
    cairo_restore(cr.get());
  }
  if (format == Format::png) {
    check(cairo_surface_write_to_png(surface.get(), out.part().c_str()), path);
  } else {
    cairo_show_page(cr.get());
    cr.reset();
    cairo_surface_finish(surface.get());
    check(cairo_surface_status(surface.get()), path);
  }
  out.commit();
  return pages;
}

}  // namespace lftag

#include "viewer/contact_sheet.h"

#include "core/errors.h"

#include <vtkFreeTypeTools.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkStdString.h>
#include <vtkTextProperty.h>

#include <algorithm>
#include <cmath>

namespace organsmith {

namespace {

/// `src` scaled to `width` (box average when shrinking, nearest when growing).
RgbImage scaled(const RgbImage& src, int width) {
  RgbImage out;
  out.width_px = width;
  out.height_px = std::max(1, int(std::lround(double(src.height_px) * width / std::max(1, src.width_px))));
  out.rgb.assign(std::size_t(out.width_px) * out.height_px * 3, 0);
  const double sx = double(src.width_px) / out.width_px, sy = double(src.height_px) / out.height_px;
  for (int y = 0; y < out.height_px; ++y)
    for (int x = 0; x < out.width_px; ++x) {
      const int x0 = int(x * sx), y0 = int(y * sy);
      const int x1 = std::max(x0 + 1, std::min(src.width_px, int((x + 1) * sx)));
      const int y1 = std::max(y0 + 1, std::min(src.height_px, int((y + 1) * sy)));
      double sum[3] = {0, 0, 0};
      for (int v = y0; v < y1; ++v)
        for (int u = x0; u < x1; ++u)
          for (int c = 0; c < 3; ++c) sum[c] += src.pixel(u, v)[c];
      const double n = double(x1 - x0) * (y1 - y0);
      for (int c = 0; c < 3; ++c) out.rgb[3 * (std::size_t(y) * out.width_px + x) + c] = std::uint8_t(sum[c] / n + 0.5);
    }
  return out;
}

void blit(RgbImage& dst, const RgbImage& src, int x0, int y0) {
  for (int y = 0; y < src.height_px && y0 + y < dst.height_px; ++y)
    std::copy_n(src.pixel(0, y), 3 * std::min(src.width_px, dst.width_px - x0),
                dst.rgb.data() + 3 * (std::size_t(y0 + y) * dst.width_px + x0));
}

/// Draws `text` with its top-left corner at (x0, y0), clipped to `max_width` pixels.
void draw_text(RgbImage& dst, const std::string& text, int x0, int y0, int max_width, const double rgb[3], int font_px) {
  vtkNew<vtkTextProperty> prop;
  prop->SetFontFamilyToArial();
  prop->SetFontSize(font_px);
  prop->SetColor(rgb[0], rgb[1], rgb[2]);
  vtkNew<vtkImageData> img;
  int dims[2] = {0, 0};
  if (!vtkFreeTypeTools::GetInstance()->RenderString(prop.Get(), vtkStdString(text), 72, img.Get(), dims)) return;
  int extent[6];
  img->GetExtent(extent);
  const int w = extent[1] - extent[0] + 1, h = extent[3] - extent[2] + 1;
  for (int y = 0; y < std::min(h, dims[1]); ++y)
    for (int x = 0; x < std::min({w, dims[0], max_width}); ++x) {
      // VTK images run bottom-up; RGBA with the glyph coverage in alpha.
      const auto* p = static_cast<unsigned char*>(img->GetScalarPointer(extent[0] + x, extent[2] + dims[1] - 1 - y, 0));
      const double a = p[3] / 255.0;
      const int X = x0 + x, Y = y0 + y;
      if (a <= 0 || X < 0 || Y < 0 || X >= dst.width_px || Y >= dst.height_px) continue;
      std::uint8_t* d = dst.rgb.data() + 3 * (std::size_t(Y) * dst.width_px + X);
      for (int c = 0; c < 3; ++c) d[c] = std::uint8_t(d[c] * (1 - a) + p[c] * a + 0.5);
    }
}

}  // namespace

RgbImage contact_sheet(const std::vector<SheetTile>& tiles, const ContactSheetOptions& o) {
  const int n = int(tiles.size());
  const int columns = o.columns > 0 ? o.columns : std::max(1, int(std::ceil(std::sqrt(double(std::max(n, 1))))));
  const int rows = std::max(1, (n + columns - 1) / columns);
  const int font_px = std::max(10, o.tile_px / 18), caption_px = font_px + 10, gap = 6;
  std::vector<RgbImage> images;
  int tile_h = 0;
  for (const auto& t : tiles) {
    RgbImage img;
    try {
      img = scaled(read_png(t.image), o.tile_px);
    } catch (const Error&) {
      img.width_px = o.tile_px;
      img.height_px = o.tile_px * 3 / 4;
      img.rgb.assign(std::size_t(img.width_px) * img.height_px * 3, 70);
      const double grey[3] = {0.8, 0.8, 0.8};
      draw_text(img, "no picture", o.tile_px / 3, img.height_px / 2 - font_px / 2, o.tile_px, grey, font_px);
    }
    tile_h = std::max(tile_h, img.height_px);
    images.push_back(std::move(img));
  }
  if (images.empty()) tile_h = o.tile_px * 3 / 4;
  RgbImage sheet;
  sheet.width_px = columns * (o.tile_px + gap) + gap;
  sheet.height_px = rows * (tile_h + caption_px + gap) + gap;
  sheet.rgb.assign(std::size_t(sheet.width_px) * sheet.height_px * 3, 255);
  for (int i = 0; i < n; ++i) {
    const int x = gap + (i % columns) * (o.tile_px + gap), y = gap + (i / columns) * (tile_h + caption_px + gap);
    blit(sheet, images[std::size_t(i)], x, y);
    const double ok[3] = {0.1, 0.1, 0.1}, bad[3] = {0.8, 0.05, 0.05};
    draw_text(sheet, tiles[std::size_t(i)].caption, x + 2, y + tile_h + 4, o.tile_px - 4, tiles[std::size_t(i)].ok ? ok : bad,
              font_px);
  }
  return sheet;
}

}  // namespace organsmith

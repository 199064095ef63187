#include "client/gl/gl_renderer.h"

// libepoxy loads the GL entry points. stb_easy_font keeps its implementation
// in the header, all of it static: this file is its only user, so the HUD
// font lives in this translation unit.
#include <epoxy/gl.h>
#include <fmt/format.h>
#include <stb/stb_easy_font.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/core/check.h"

namespace vistream {
namespace {

// stb_easy_font's glyphs are about 7 px tall on a 12 px line; doubled, the
// HUD reads at a normal viewing distance on a 640 x 480 window and up.
// Smaller windows, or text that would cover half of one, get single size.
constexpr float kHudScale = 2.0f;
constexpr float kHudSmallScale = 1.0f;
constexpr float kHudMarginPx = 4.0f;    // from the window corner to the box
constexpr float kHudPaddingPx = 4.0f;   // from the box edge to the text
constexpr float kHudLineUnits = 12.0f;  // stb_easy_font's line pitch, in font units

// stb_easy_font only knows printable ASCII and takes a mutable string.
std::string printable(std::string text) {
  for (char& c : text)
    if (c < 32 || c > 126) c = '?';
  return text;
}

float fontWidthUnits(std::string text) {
  return float(stb_easy_font_width(text.data()));
}

// Packs `parts` joined by `joiner` into lines no wider than `maxUnits`; a
// part wider than that on its own gets a line of its own (and `fits` false).
std::vector<std::string> packParts(const std::vector<std::string>& parts, const std::string& joiner,
                                   float maxUnits, const std::string& indent, bool& fits) {
  std::vector<std::string> out;
  std::string line;
  for (const std::string& part : parts) {
    const std::string candidate =
        line.empty() ? (out.empty() ? "" : indent) + part : line + joiner + part;
    if (line.empty() || fontWidthUnits(candidate) <= maxUnits) {
      line = candidate;
    } else {
      out.push_back(line);
      line = indent + part;
    }
    if (fontWidthUnits(line) > maxUnits) fits = false;
  }
  if (!line.empty()) out.push_back(line);
  return out;
}

std::vector<std::string> splitOn(const std::string& text, const std::string& separator) {
  std::vector<std::string> parts;
  for (size_t pos = 0;;) {
    const size_t next = text.find(separator, pos);
    std::string part = text.substr(pos, next == std::string::npos ? std::string::npos : next - pos);
    if (!part.empty()) parts.push_back(part);
    if (next == std::string::npos) break;
    pos = next + separator.size();
  }
  return parts;
}

// Wraps one line: at field separators (two spaces) first; a field still too
// wide is wrapped at single spaces.
std::vector<std::string> wrapHudLine(const std::string& text, float maxUnits, bool& fits) {
  if (fontWidthUnits(text) <= maxUnits) return {text};
  std::vector<std::string> fields;
  for (const std::string& field : splitOn(text, "  ")) {
    if (fontWidthUnits("  " + field) <= maxUnits) {
      fields.push_back(field);
      continue;
    }
    bool wordsFit = true;
    for (const std::string& piece : packParts(splitOn(field, " "), " ", maxUnits, "  ", wordsFit))
      fields.push_back(piece.rfind("  ", 0) == 0 ? piece.substr(2) : piece);
    if (!wordsFit) fits = false;
  }
  return packParts(fields, "  ", maxUnits, "  ", fits);
}

// The near field: vertices 3t, 3t + 1, 3t + 2 are triangle t's corners
// (the draw's indices are vertex numbers, so gl_VertexID names them), and
// each fragment looks its colour up in the triangle's lighting grid exactly
// as LightingGrid::colourAt and Haze::apply do on the CPU, so the framebuffer
// byte equals the CPU's byte up to the rounding of the last float bit.
constexpr const char* kNearVertex = R"(#version 330 core
layout(location = 0) in vec3 position;
uniform mat4 rotationProjection;
uniform vec3 eye;
flat out int triangle;
out vec2 bary;
out vec3 fromEye;
void main() {
  // Relative to the eye first, so positions far from the origin keep their precision.
  fromEye = position - eye;
  gl_Position = rotationProjection * vec4(fromEye, 1.0);
  triangle = gl_VertexID / 3;
  int k = gl_VertexID - 3 * triangle;
  bary = vec2(k == 1 ? 1.0 : 0.0, k == 2 ? 1.0 : 0.0);
}
)";
// Fragments beyond the near-field distance are left to the far field.
constexpr const char* kNearFragment = R"(#version 330 core
flat in int triangle;
in vec2 bary;
in vec3 fromEye;
uniform float maxDistance;
uniform usamplerBuffer grids;   // per triangle: first colour, level
uniform samplerBuffer colours;  // the grids' colours, RGBA8
uniform vec3 hazeColour;        // 0..255
uniform float hazeScale;        // metres, 0: no haze
out vec4 fragColour;
vec3 point(int first, int n, int i, int j) {
  return texelFetch(colours, first + j * (n + 1) - j * (j - 1) / 2 + i).rgb * 255.0;
}
void main() {
  float distance = length(fromEye);
  if (distance > maxDistance) discard;
  uvec2 g = texelFetch(grids, triangle).rg;
  int first = int(g.r), n = int(g.g);
  float u = clamp(bary.x, 0.0, 1.0);
  float v = clamp(bary.y, 0.0, 1.0 - u);
  float x = u * float(n), y = v * float(n);
  int i = min(int(x), n - 1), j = min(int(y), n - 1);
  if (i + j > n - 1) i -= 1;
  float fx = x - float(i), fy = y - float(j);
  vec3 c;
  if (fx + fy > 1.0 && i + j + 2 <= n)
    c = point(first, n, i + 1, j + 1) * (fx + fy - 1.0) + point(first, n, i, j + 1) * (1.0 - fx) +
        point(first, n, i + 1, j) * (1.0 - fy);
  else
    c = point(first, n, i, j) * (1.0 - fx - fy) + point(first, n, i + 1, j) * fx +
        point(first, n, i, j + 1) * fy;
  if (hazeScale > 0.0 && distance > 0.0)
    c = c + (hazeColour - c) * (1.0 - exp(-distance / hazeScale));
  fragColour = vec4(clamp(c, 0.0, 255.0) / 255.0, 1.0);
}
)";

// The far-field image: one triangle covering the viewport, each pixel
// fetching exactly its texel. The image is uploaded top row first, so texture
// row 0 is the top of the screen while gl_FragCoord counts from the bottom.
constexpr const char* kImageVertex = R"(#version 330 core
void main() {
  const vec2 corners[3] = vec2[3](vec2(-1.0, -1.0), vec2(3.0, -1.0), vec2(-1.0, 3.0));
  gl_Position = vec4(corners[gl_VertexID], 0.0, 1.0);
}
)";
constexpr const char* kImageFragment = R"(#version 330 core
uniform sampler2D image;
out vec4 fragColour;
void main() {
  ivec2 size = textureSize(image, 0);
  ivec2 p = ivec2(gl_FragCoord.xy);
  fragColour = vec4(texelFetch(image, ivec2(p.x, size.y - 1 - p.y), 0).rgb, 1.0);
}
)";

// The far-field image with its depth limits (GpuImpostors::depthLimit, a
// view depth per pixel) written as depth, so that the impostors' points that
// follow show only where the software compose would show them.
constexpr const char* kImageDepthFragment = R"(#version 330 core
uniform sampler2D image;
uniform sampler2D limit;
uniform float depthRange;
out vec4 fragColour;
void main() {
  ivec2 size = textureSize(image, 0);
  ivec2 p = ivec2(gl_FragCoord.xy);
  ivec2 texel = ivec2(p.x, size.y - 1 - p.y);
  fragColour = vec4(texelFetch(image, texel, 0).rgb, 1.0);
  gl_FragDepth = clamp(texelFetch(limit, texel, 0).r / depthRange, 0.0, 1.0);
}
)";

// Point-based impostors (Wimmer 2001, section 5.4.3), what the thesis's
// vertex program did: each point takes its colour seen from the eye (the
// texel footprint where the line from the eye through the point crosses the
// sampling plane, bilinear between the point's texels, as
// Impostor::colourSeenFrom), covers the pixels of the 2x2 round its
// projection (a point of size 2) whose centres lie within the splat's radius
// and is depth tested by its score (PointSplat::score: the view depth,
// linear, raised off the point's centre), so the depth limits of the
// far-field image compare as in the software splat.
constexpr const char* kPointVertex = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in uint texel;  // the point's first texel; the top bit: one colour
uniform mat4 rotationProjection;
uniform vec3 eye;
uniform vec3 planeOrigin;
uniform vec3 planeU;
uniform vec3 planeV;
uniform vec3 planeNormal;
uniform ivec2 texels;               // texture width and height a point
uniform samplerBuffer colours;      // RGBA8
uniform float depthRange;
flat out vec3 colour;
flat out float depth;
vec3 at(int first, int i, int j) {
  return texelFetch(colours, first + j * texels.x + i).rgb * 255.0;
}
void main() {
  vec3 rel = position - eye;
  gl_Position = rotationProjection * vec4(rel, 1.0);
  depth = gl_Position.w / depthRange;
  int first = int(texel & 0x7fffffffu);
  if ((texel & 0x80000000u) != 0u) {
    colour = at(first, 0, 0);
    return;
  }
  float across = dot(planeNormal, rel);
  vec3 x = eye;
  if (abs(across) > 1e-12 * dot(rel, rel)) x = eye + rel * (dot(planeNormal, planeOrigin - eye) / across);
  vec3 r = x - planeOrigin;
  vec2 st = vec2(dot(r, planeU) / dot(planeU, planeU), dot(r, planeV) / dot(planeV, planeV));
  float fx = clamp(st.x * float(texels.x) - 0.5, 0.0, float(texels.x - 1));
  float fy = clamp(st.y * float(texels.y) - 0.5, 0.0, float(texels.y - 1));
  int i0 = min(int(fx), texels.x - 1), j0 = min(int(fy), texels.y - 1);
  int i1 = min(i0 + 1, texels.x - 1), j1 = min(j0 + 1, texels.y - 1);
  float ax = fx - float(i0), ay = fy - float(j0);
  colour = (at(first, i0, j0) * (1.0 - ax) + at(first, i1, j0) * ax) * (1.0 - ay) +
           (at(first, i0, j1) * (1.0 - ax) + at(first, i1, j1) * ax) * ay;
}
)";
constexpr const char* kPointFragment = R"(#version 330 core
flat in vec3 colour;
flat in float depth;
uniform float radius2;          // PointSplat::radius squared, pixels
uniform float sameSurfaceScale; // PointSplat::sameSurface / radius2
out vec4 fragColour;
void main() {
  vec2 d = (gl_PointCoord - 0.5) * 2.0;  // from the point's centre, pixels (a point of size 2)
  float d2 = dot(d, d);
  if (d2 > radius2) discard;
  gl_FragDepth = depth * (1.0 + sameSurfaceScale * d2);
  fragColour = vec4(clamp(colour, 0.0, 255.0) / 255.0, 1.0);
}
)";

// The HUD: positions in pixels, row 0 at the top, one colour per draw.
constexpr const char* kHudVertex = R"(#version 330 core
layout(location = 0) in vec2 pixel;
uniform vec2 viewport;
void main() {
  gl_Position = vec4(pixel.x / viewport.x * 2.0 - 1.0, 1.0 - pixel.y / viewport.y * 2.0, 0.0, 1.0);
}
)";
constexpr const char* kHudFragment = R"(#version 330 core
uniform vec4 colour;
out vec4 fragColour;
void main() { fragColour = colour; }
)";

// One OpenGL object name, made with `gen` (a glGen* function) and deleted
// with `del` (the matching glDelete*) when this goes; needs a current context
// for its whole life.
template <auto& gen, auto& del>
struct GlName {
  GLuint id = 0;
  GlName() { gen(1, &id); }
  ~GlName() { del(1, &id); }
  GlName(const GlName&) = delete;
  GlName& operator=(const GlName&) = delete;
};

using Buffer = GlName<glGenBuffers, glDeleteBuffers>;
using VertexArray = GlName<glGenVertexArrays, glDeleteVertexArrays>;
using Texture = GlName<glGenTextures, glDeleteTextures>;

struct Shader {
  GLuint id = 0;
  Shader(GLenum type, const char* source) : id(glCreateShader(type)) {
    glShaderSource(id, 1, &source, nullptr);
    glCompileShader(id);
    GLint ok = GL_FALSE;
    glGetShaderiv(id, GL_COMPILE_STATUS, &ok);
    if (ok != GL_TRUE) {
      const std::string log = infoLog();
      glDeleteShader(id);
      throw std::runtime_error("OpenGL shader does not compile: " + log);
    }
  }
  ~Shader() { glDeleteShader(id); }
  Shader(const Shader&) = delete;
  Shader& operator=(const Shader&) = delete;

  std::string infoLog() const {
    GLint length = 0;
    glGetShaderiv(id, GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetShaderInfoLog(id, GLsizei(log.size()), nullptr, log.data());
    return log.c_str();
  }
};

struct Program {
  GLuint id = 0;
  Program(const char* vertexSource, const char* fragmentSource) {
    const Shader vertex(GL_VERTEX_SHADER, vertexSource);
    const Shader fragment(GL_FRAGMENT_SHADER, fragmentSource);
    id = glCreateProgram();
    glAttachShader(id, vertex.id);
    glAttachShader(id, fragment.id);
    glLinkProgram(id);
    glDetachShader(id, vertex.id);
    glDetachShader(id, fragment.id);
    GLint ok = GL_FALSE;
    glGetProgramiv(id, GL_LINK_STATUS, &ok);
    if (ok != GL_TRUE) {
      GLint length = 0;
      glGetProgramiv(id, GL_INFO_LOG_LENGTH, &length);
      std::string log(size_t(std::max(length, 1)), '\0');
      glGetProgramInfoLog(id, GLsizei(log.size()), nullptr, log.data());
      glDeleteProgram(id);
      throw std::runtime_error("OpenGL program does not link: " + std::string(log.c_str()));
    }
  }
  ~Program() { glDeleteProgram(id); }
  Program(const Program&) = delete;
  Program& operator=(const Program&) = delete;

  GLint uniform(const char* name) const { return glGetUniformLocation(id, name); }
};

// A texture buffer: a buffer object read in shaders through a buffer texture.
struct TextureBuffer {
  Buffer buffer;
  Texture texture;

  template <class T>
  void upload(GLenum format, const std::vector<T>& data) {
    glBindBuffer(GL_TEXTURE_BUFFER, buffer.id);
    glBufferData(GL_TEXTURE_BUFFER, GLsizeiptr(std::max<size_t>(1, data.size()) * sizeof(T)),
                 data.empty() ? nullptr : data.data(), GL_STATIC_DRAW);
    glBindTexture(GL_TEXTURE_BUFFER, texture.id);
    glTexBuffer(GL_TEXTURE_BUFFER, format, buffer.id);
    glBindBuffer(GL_TEXTURE_BUFFER, 0);
  }
  void bind(GLenum unit) const {
    glActiveTexture(unit);
    glBindTexture(GL_TEXTURE_BUFFER, texture.id);
  }
};

// One vertex as stb_easy_font writes it.
struct FontVertex {
  float x, y, z;
  uint8_t rgba[4];
};
static_assert(sizeof(FontVertex) == 16);

}  // namespace

struct GlRenderer::Impl {
  Program nearProgram{kNearVertex, kNearFragment};
  Program imageProgram{kImageVertex, kImageFragment};
  Program imageDepthProgram{kImageVertex, kImageDepthFragment};
  Program pointProgram{kPointVertex, kPointFragment};
  Program hudProgram{kHudVertex, kHudFragment};
  GLint rotationProjection = nearProgram.uniform("rotationProjection");
  GLint eye = nearProgram.uniform("eye");
  GLint maxDistance = nearProgram.uniform("maxDistance");
  GLint grids = nearProgram.uniform("grids");
  GLint colours = nearProgram.uniform("colours");
  GLint hazeColour = nearProgram.uniform("hazeColour");
  GLint hazeScale = nearProgram.uniform("hazeScale");
  GLint image = imageProgram.uniform("image");
  GLint depthImage = imageDepthProgram.uniform("image");
  GLint depthLimit = imageDepthProgram.uniform("limit");
  GLint imageDepthRange = imageDepthProgram.uniform("depthRange");
  struct PointUniforms {
    GLint rotationProjection, eye, planeOrigin, planeU, planeV, planeNormal, texels, colours,
        depthRange, radius2, sameSurfaceScale;
  };
  PointUniforms point{pointProgram.uniform("rotationProjection"),
                      pointProgram.uniform("eye"),
                      pointProgram.uniform("planeOrigin"),
                      pointProgram.uniform("planeU"),
                      pointProgram.uniform("planeV"),
                      pointProgram.uniform("planeNormal"),
                      pointProgram.uniform("texels"),
                      pointProgram.uniform("colours"),
                      pointProgram.uniform("depthRange"),
                      pointProgram.uniform("radius2"),
                      pointProgram.uniform("sameSurfaceScale")};
  GLint hudViewport = hudProgram.uniform("viewport");
  GLint hudColour = hudProgram.uniform("colour");

  // Triangles with their colour grids: the static near field, and the
  // dynamic objects (avatars), uploaded every frame they change.
  struct TriangleSet {
    VertexArray array;
    Buffer vertices;
    Buffer indices;
    TextureBuffer grids, colours;
    Haze haze;
    size_t triangleCount = 0;

    TriangleSet() {
      glBindVertexArray(array.id);
      glBindBuffer(GL_ARRAY_BUFFER, vertices.id);
      glEnableVertexAttribArray(0);
      glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(glm::vec3), nullptr);
      glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, indices.id);  // recorded in the vertex array
      glBindVertexArray(0);
    }
    void upload(const RenderGeometry& geometry, GLenum usage) {
      const size_t n = geometry.size();
      VS_CHECK_EQ(geometry.triangles.positions.size(), 3 * n);
      const LightingGrid& lighting = geometry.lighting;
      VS_CHECK_EQ(lighting.size(), n);
      glBindBuffer(GL_ARRAY_BUFFER, vertices.id);
      glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(std::max<size_t>(1, 3 * n) * sizeof(glm::vec3)),
                   n ? geometry.triangles.positions.data() : nullptr, usage);
      std::vector<glm::uvec2> g(n);
      for (size_t t = 0; t < n; ++t) g[t] = glm::uvec2(lighting.first[t], lighting.level[t]);
      std::vector<glm::u8vec4> c(lighting.colours.size());
      for (size_t i = 0; i < c.size(); ++i) c[i] = glm::u8vec4(lighting.colours[i], 255);
      GLint maxTexels = 0;
      glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &maxTexels);
      if (size_t(maxTexels) < std::max(g.size(), c.size()))
        throw std::runtime_error(fmt::format(
            "OpenGL: {} lighting colours exceed this driver's texture buffer limit of {} texels",
            c.size(), maxTexels));
      grids.upload(GL_RG32UI, g);
      colours.upload(GL_RGBA8, c);
      haze = geometry.haze;
      triangleCount = n;
    }
  };
  TriangleSet staticSet, dynamicSet;
  std::vector<GLuint> indices;  // scratch, reused every frame

  // One impostor's points on the GPU: positions, per point its first texel
  // (the top bit set for a single-colour point), the texels.
  struct PointSet {
    VertexArray array;
    Buffer positions, texelOffsets;
    TextureBuffer colours;
    size_t count = 0;

    explicit PointSet(const Impostor& imp) : count(imp.size()) {
      std::vector<uint32_t> offsets(imp.size());
      for (size_t k = 0; k < imp.size(); ++k)
        offsets[k] = imp.firstTexel[k] | (imp.singleColour[k] ? 0x80000000u : 0u);
      std::vector<glm::u8vec4> texels(imp.texels.size());
      for (size_t i = 0; i < texels.size(); ++i) texels[i] = glm::u8vec4(imp.texels[i], 255);
      glBindVertexArray(array.id);
      glBindBuffer(GL_ARRAY_BUFFER, positions.id);
      glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(std::max<size_t>(1, count) * sizeof(glm::vec3)),
                   count ? imp.points.data() : nullptr, GL_STATIC_DRAW);
      glEnableVertexAttribArray(0);
      glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(glm::vec3), nullptr);
      glBindBuffer(GL_ARRAY_BUFFER, texelOffsets.id);
      glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(std::max<size_t>(1, count) * sizeof(uint32_t)),
                   count ? offsets.data() : nullptr, GL_STATIC_DRAW);
      glEnableVertexAttribArray(1);
      glVertexAttribIPointer(1, 1, GL_UNSIGNED_INT, sizeof(uint32_t), nullptr);
      glBindVertexArray(0);
      glBindBuffer(GL_ARRAY_BUFFER, 0);
      colours.upload(GL_RGBA8, texels);
    }
  };
  // Impostors uploaded, most recently drawn last; the shared pointer keeps
  // an impostor's address from being reused while its points are here.
  std::vector<std::pair<std::shared_ptr<const Impostor>, std::unique_ptr<PointSet>>> pointSets;
  static constexpr size_t kPointSetsKept = 64;

  VertexArray emptyArray;  // core profile draws need a bound vertex array
  Texture farTexture, limitTexture;
  int farWidth = 0, farHeight = 0, limitWidth = 0, limitHeight = 0;

  VertexArray hudArray;
  Buffer hudVertices;
  std::vector<glm::vec2> hudScratch;

  Impl() {
    glBindVertexArray(hudArray.id);
    glBindBuffer(GL_ARRAY_BUFFER, hudVertices.id);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, sizeof(glm::vec2), nullptr);
    glBindVertexArray(0);

    for (GLuint id : {farTexture.id, limitTexture.id}) {
      glBindTexture(GL_TEXTURE_2D, id);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, 0);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    }
  }

  // The far-field image, and with `limits` (one view depth a pixel) the
  // depth each of its pixels leaves for the impostors' points.
  void drawFarField(const ImageRgb8& farField, const std::vector<float>* limits = nullptr,
                    float depthRange = 1.0f) {
    if (limits) {
      glActiveTexture(GL_TEXTURE1);
      glBindTexture(GL_TEXTURE_2D, limitTexture.id);
      glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
      if (farField.width != limitWidth || farField.height != limitHeight) {
        glTexImage2D(GL_TEXTURE_2D, 0, GL_R32F, farField.width, farField.height, 0, GL_RED,
                     GL_FLOAT, limits->data());
        limitWidth = farField.width;
        limitHeight = farField.height;
      } else {
        glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, farField.width, farField.height, GL_RED, GL_FLOAT,
                        limits->data());
      }
      glActiveTexture(GL_TEXTURE0);
    }
    glBindTexture(GL_TEXTURE_2D, farTexture.id);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    if (farField.width != farWidth || farField.height != farHeight) {
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, farField.width, farField.height, 0, GL_RGB,
                   GL_UNSIGNED_BYTE, farField.pixels.data());
      farWidth = farField.width;
      farHeight = farField.height;
    } else {
      glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, farField.width, farField.height, GL_RGB,
                      GL_UNSIGNED_BYTE, farField.pixels.data());
    }
    if (limits) {
      glUseProgram(imageDepthProgram.id);
      glUniform1i(depthImage, 0);
      glUniform1i(depthLimit, 1);
      glUniform1f(imageDepthRange, depthRange);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_ALWAYS);
    } else {
      glUseProgram(imageProgram.id);
      glUniform1i(image, 0);
    }
    glActiveTexture(GL_TEXTURE0);
    glBindVertexArray(emptyArray.id);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glDisable(GL_DEPTH_TEST);
  }

  PointSet& pointSetOf(const std::shared_ptr<const Impostor>& imp) {
    auto it = std::find_if(pointSets.begin(), pointSets.end(),
                           [&](const auto& entry) { return entry.first == imp; });
    if (it == pointSets.end()) {
      if (pointSets.size() >= kPointSetsKept) pointSets.erase(pointSets.begin());
      pointSets.emplace_back(imp, std::make_unique<PointSet>(*imp));
      return *pointSets.back().second;
    }
    std::rotate(it, it + 1, pointSets.end());  // most recently drawn last
    return *pointSets.back().second;
  }

  // The impostors' points, depth tested against the far-field image's limits.
  void drawPoints(const Camera& camera, const GpuImpostors& gpu, float depthRange) {
    glUseProgram(pointProgram.id);
    const glm::mat4 rp = camera.rotationProjection();
    glUniformMatrix4fv(point.rotationProjection, 1, GL_FALSE, &rp[0][0]);
    glUniform3f(point.eye, camera.eye.x, camera.eye.y, camera.eye.z);
    glUniform1i(point.colours, 1);
    glUniform1f(point.depthRange, depthRange);
    const float radius2 = gpu.splat.radius * gpu.splat.radius;
    glUniform1f(point.radius2, radius2);
    glUniform1f(point.sameSurfaceScale, gpu.splat.sameSurface / radius2);
    // Strictly nearer: of two points at one depth the first drawn keeps the
    // pixel, as in the software splat.
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glPointSize(2.0f);
    for (const std::shared_ptr<const Impostor>& imp : gpu.impostors) {
      if (!imp || imp->size() == 0) continue;
      PointSet& set = pointSetOf(imp);
      const SamplingPlane& pl = imp->plane;
      glUniform3f(point.planeOrigin, pl.origin.x, pl.origin.y, pl.origin.z);
      glUniform3f(point.planeU, pl.uAxis.x, pl.uAxis.y, pl.uAxis.z);
      glUniform3f(point.planeV, pl.vAxis.x, pl.vAxis.y, pl.vAxis.z);
      glUniform3f(point.planeNormal, pl.normal.x, pl.normal.y, pl.normal.z);
      glUniform2i(point.texels, GLint(imp->textureWidth), GLint(imp->textureHeight));
      set.colours.bind(GL_TEXTURE1);
      glBindVertexArray(set.array.id);
      glDrawArrays(GL_POINTS, 0, GLsizei(set.count));
    }
    glActiveTexture(GL_TEXTURE0);
    glDisable(GL_DEPTH_TEST);
  }

  // Triangles `which` of `set` (all of them if null) with a depth test.
  void drawSet(const Camera& camera, TriangleSet& set, const std::span<const uint32_t>* which,
               float nearDistance) {
    const size_t count = which ? which->size() : set.triangleCount;
    if (count == 0) return;
    indices.resize(3 * count);
    for (size_t i = 0; i < count; ++i) {
      const uint32_t t = which ? (*which)[i] : uint32_t(i);
      VS_CHECK_LT(size_t(t), set.triangleCount);
      indices[3 * i] = 3 * t;
      indices[3 * i + 1] = 3 * t + 1;
      indices[3 * i + 2] = 3 * t + 2;
    }
    glBindVertexArray(set.array.id);
    const GLsizeiptr bytes = GLsizeiptr(indices.size() * sizeof(GLuint));
    // Orphan last frame's list, so the driver need not wait for the GPU to finish with it.
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, bytes, nullptr, GL_STREAM_DRAW);
    glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, 0, bytes, indices.data());
    glUseProgram(nearProgram.id);
    const glm::mat4 rp = camera.rotationProjection();
    glUniformMatrix4fv(rotationProjection, 1, GL_FALSE, &rp[0][0]);
    glUniform3f(eye, camera.eye.x, camera.eye.y, camera.eye.z);
    glUniform1f(maxDistance, std::isfinite(nearDistance) ? nearDistance : 3.0e38f);
    glUniform1i(grids, 1);
    glUniform1i(colours, 2);
    glUniform3f(hazeColour, set.haze.colour.r, set.haze.colour.g, set.haze.colour.b);
    glUniform1f(hazeScale, set.haze.scale);
    set.grids.bind(GL_TEXTURE1);
    set.colours.bind(GL_TEXTURE2);
    glActiveTexture(GL_TEXTURE0);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDrawElements(GL_TRIANGLES, GLsizei(indices.size()), GL_UNSIGNED_INT, nullptr);
    glDisable(GL_DEPTH_TEST);
  }

  void drawHud(const Camera& camera, std::span<const HudLine> hud) {
    if (hud.empty()) return;
    const HudLayout layout = layoutHud(hud, camera.width, camera.height);
    // The box first (6 vertices), then the text as triangles.
    hudScratch.assign(6, glm::vec2(0.0f));
    std::vector<char> font;
    for (size_t i = 0; i < layout.lines.size(); ++i) {
      std::string text = layout.lines[i];
      font.resize(text.size() * 1024 + 64);  // 16 quads a character, more than any glyph needs
      const int quads = stb_easy_font_print(0.0f, float(i) * kHudLineUnits, text.data(), nullptr,
                                            font.data(), int(font.size()));
      for (int q = 0; q < quads; ++q) {
        FontVertex v[4];
        std::memcpy(v, font.data() + size_t(q) * sizeof(v), sizeof(v));
        for (int k : {0, 1, 2, 0, 2, 3})
          hudScratch.push_back(kHudMarginPx + kHudPaddingPx +
                               layout.scale * glm::vec2(v[k].x, v[k].y));
      }
    }
    const glm::vec2 lo = layout.boxLo, hi = layout.boxHi;
    const glm::vec2 box[6] = {lo, {hi.x, lo.y}, hi, lo, hi, {lo.x, hi.y}};
    std::copy(std::begin(box), std::end(box), hudScratch.begin());

    glBindVertexArray(hudArray.id);
    glBindBuffer(GL_ARRAY_BUFFER, hudVertices.id);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(hudScratch.size() * sizeof(glm::vec2)),
                 hudScratch.data(), GL_STREAM_DRAW);
    glUseProgram(hudProgram.id);
    glUniform2f(hudViewport, float(camera.width), float(camera.height));
    glEnable(GL_BLEND);
    glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    glUniform4f(hudColour, 0.0f, 0.0f, 0.0f, 0.6f);
    glDrawArrays(GL_TRIANGLES, 0, 6);
    glDisable(GL_BLEND);
    glUniform4f(hudColour, 1.0f, 1.0f, 1.0f, 1.0f);
    glDrawArrays(GL_TRIANGLES, 6, GLsizei(hudScratch.size() - 6));
  }
};

HudLayout layoutHud(std::span<const HudLine> hud, int width, int height) {
  HudLayout layout;
  if (hud.empty()) return layout;
  const float inner = std::max(0.0f, float(width) - 2.0f * (kHudMarginPx + kHudPaddingPx));
  for (const float scale : {kHudScale, kHudSmallScale}) {
    layout.scale = scale;
    layout.lines.clear();
    bool fits = true;
    for (const HudLine& line : hud)
      for (std::string& wrapped : wrapHudLine(printable(line.text), inner / scale, fits))
        layout.lines.push_back(std::move(wrapped));
    const float textHeight = scale * (float(layout.lines.size()) * kHudLineUnits - 2.0f);
    if (fits && textHeight + 2.0f * (kHudMarginPx + kHudPaddingPx) <= 0.5f * float(height)) break;
  }
  float widthUnits = 0.0f;
  for (const std::string& line : layout.lines)
    widthUnits = std::max(widthUnits, fontWidthUnits(line));
  layout.boxLo = glm::vec2(kHudMarginPx);
  layout.boxHi =
      layout.boxLo + 2.0f * kHudPaddingPx +
      layout.scale * glm::vec2(widthUnits, float(layout.lines.size()) * kHudLineUnits - 2.0f);
  return layout;
}

GlRenderer::GlRenderer() : impl_(std::make_unique<Impl>()) {}

GlRenderer::~GlRenderer() = default;

void GlRenderer::upload(const RenderGeometry& geometry) {
  impl_->staticSet.upload(geometry, GL_STATIC_DRAW);
}

void GlRenderer::uploadDynamic(const RenderGeometry& geometry) {
  impl_->dynamicSet.upload(geometry, GL_STREAM_DRAW);
}

void GlRenderer::draw(const Camera& camera, const ImageRgb8& farField,
                      std::span<const uint32_t> near, float nearDistance,
                      std::span<const HudLine> hud, const GpuImpostors* impostors) {
  // Every byte drawn is a byte computed on the CPU: no dithering, no sRGB
  // conversion, no multisampling; triangles are two-sided.
  glDisable(GL_DITHER);
  glDisable(GL_FRAMEBUFFER_SRGB);
  glDisable(GL_MULTISAMPLE);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_TEST);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  glDepthMask(GL_TRUE);
  glViewport(0, 0, camera.width, camera.height);

  const bool farFits =
      farField.width == camera.width && farField.height == camera.height && farField.width > 0 &&
      farField.height > 0 &&
      farField.pixels.size() == size_t(farField.width) * size_t(farField.height) * 3;
  const bool points = farFits && impostors && !impostors->impostors.empty() &&
                      impostors->depthLimit.size() == farField.pixels.size() / 3;
  if (points) {
    // Linear view depth over the range the points span (to their boxes'
    // farthest corner), so that 24 bits tell points apart as finely as the
    // software splat's floats mostly do; a limit beyond the range passes
    // every point, as it should.
    float range = 1.0f;
    for (const auto& imp : impostors->impostors)
      if (imp)
        for (int k = 0; k < 8; ++k) {
          const glm::vec3 corner = imp->box.corner(k);
          range = std::max(
              range,
              (1.01f + impostors->splat.sameSurface) * glm::length(corner - camera.eye) + 1.0f);
        }
    glClearDepth(1.0);
    glClear(GL_DEPTH_BUFFER_BIT);
    impl_->drawFarField(farField, &impostors->depthLimit, range);
    impl_->drawPoints(camera, *impostors, range);
  } else if (farFits) {
    impl_->drawFarField(farField);
  }
  if (farFits) {
    glClearDepth(1.0);
    glClear(GL_DEPTH_BUFFER_BIT);
  } else {
    glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
    glClearDepth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  }
  impl_->drawSet(camera, impl_->staticSet, &near, nearDistance);
  impl_->drawSet(camera, impl_->dynamicSet, nullptr, nearDistance);
  impl_->drawHud(camera, hud);
  glBindVertexArray(0);
  glUseProgram(0);
}

void GlRenderer::finish() const {
  glFinish();
}

ImageRgb8 GlRenderer::readBack(int width, int height) const {
  ImageRgb8 out(width, height);
  const size_t row = size_t(width) * 3;
  std::vector<uint8_t> bottomUp(row * size_t(height));
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, bottomUp.data());
  for (int y = 0; y < height; ++y)
    std::memcpy(out.pixels.data() + size_t(y) * row, bottomUp.data() + size_t(height - 1 - y) * row,
                row);
  return out;
}

}  // namespace vistream

// texstream-render [--config FILE] [--set part.key=value]...  (render_main.cpp holds the command line)
#include "texstream/render/app/renderer_app.hpp"

int main(int argc, char** argv) { return texstream::render::render_main(argc, argv, "texstream-render"); }
